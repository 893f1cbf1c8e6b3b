//! The HTTP/JSON service: routes, wire types, errors, metrics and the serve loop.

pub mod error;
pub mod routes;
pub mod server;
pub mod telemetry;
pub mod types;

pub use error::ApiError;
pub use routes::{AppState, router};
pub use server::{LogFormat, ServerConfig, ServerError, serve};
pub use types::Limits;
