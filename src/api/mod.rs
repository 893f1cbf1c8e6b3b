//! The HTTP/JSON service: routes, wire types, errors, metrics and the serve loop; the page at
//! `/` and fits answered as pictures.

pub mod error;
pub mod linger;
pub mod page;
pub mod picture;
pub mod routes;
pub mod server;
pub mod telemetry;
pub mod types;

#[cfg(test)]
mod tests;

pub use error::{ApiError, ErrorCode};
pub use routes::{AppState, router};
pub use server::{ConfigError, LogFormat, ServerConfig, ServerError, ValidServerConfig, serve};
pub use types::Limits;
