//! The validated server configuration and the serve loop with graceful shutdown.

use std::net::SocketAddr;
use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::Ordering;
use std::time::Duration;

use serde::Serialize;
use tokio::net::TcpListener;

use super::routes::{AppState, router};
use super::types::Limits;
use crate::model::ModelError;
use crate::registry::{RegistryError, load_all};
use crate::threads::Threads;

/// Log output format.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, clap::ValueEnum)]
#[serde(rename_all = "snake_case")]
pub enum LogFormat {
    Text,
    Json,
}

/// A checked server configuration.
#[derive(Debug, Clone, Serialize)]
pub struct ServerConfig {
    pub addr: SocketAddr,
    pub models: PathBuf,
    pub body_limit: usize,
    pub limits: Limits,
    pub queue_capacity: usize,
    pub request_timeout: Duration,
    pub workers: usize,
    /// Threads of the one pool every fit computes on (forward pass, k-means, silhouettes); a fit
    /// alone uses them all, fits at once share them. 1: no pool, each fit on its worker thread.
    pub fit_threads: usize,
    pub log_format: LogFormat,
}

/// Why the server could not start or stopped with an error.
#[derive(Debug, thiserror::Error)]
pub enum ServerError {
    #[error("invalid configuration: {0}")]
    Config(String),
    #[error("cannot listen on {addr}: {source}")]
    Bind {
        addr: SocketAddr,
        source: std::io::Error,
    },
    #[error("cannot load models: {0}")]
    Models(#[from] RegistryError),
    #[error("server failed: {0}")]
    Io(#[from] std::io::Error),
}

impl ServerConfig {
    /// Checks ranges; returns the config unchanged when valid.
    pub fn validate(self) -> Result<Self, ServerError> {
        let bad = |m: &str| Err(ServerError::Config(m.to_string()));
        if self.body_limit < 1024 {
            return bad("body limit must be at least 1024 bytes");
        }
        if self.limits.max_points < 2 {
            return bad("max points must be at least 2");
        }
        if self.limits.max_frames < 2 {
            return bad("max frames must be at least 2");
        }
        if self.limits.max_k_max == 0 {
            return bad("max k_max must be at least 1");
        }
        if self.limits.max_batch == 0 {
            return bad("max batch must be at least 1");
        }
        if self.workers == 0 {
            return bad("workers must be at least 1");
        }
        if self.fit_threads == 0 {
            return bad("fit threads must be at least 1");
        }
        if self.request_timeout.is_zero() {
            return bad("request timeout must be positive");
        }
        Ok(self)
    }
}

/// Binds, loads every model (the service answers 503 on /health/ready until then), serves until
/// SIGTERM or Ctrl-C, then stops accepting, finishes in-flight requests and returns.
/// `on_bound` receives the bound address (useful with port 0).
pub async fn serve(
    config: ServerConfig,
    on_bound: impl FnOnce(SocketAddr),
) -> Result<(), ServerError> {
    let listener = TcpListener::bind(config.addr)
        .await
        .map_err(|source| ServerError::Bind {
            addr: config.addr,
            source,
        })?;
    let addr = listener.local_addr()?;
    let state = Arc::new(AppState::new(
        config.limits,
        config.workers,
        config.queue_capacity,
        config.request_timeout,
    ));
    let app = router(state.clone(), config.body_limit);
    tracing::info!(%addr, "listening");
    on_bound(addr);

    let (failed_tx, failed_rx) = tokio::sync::oneshot::channel::<RegistryError>();
    let loader_state = state.clone();
    let dir = config.models.clone();
    let fit_threads = config.fit_threads;
    tokio::task::spawn_blocking(move || {
        let loaded = Threads::new(fit_threads)
            .map_err(|e| {
                RegistryError::Weights(ModelError::Config(format!(
                    "cannot start {fit_threads} fit threads: {e}"
                )))
            })
            .and_then(|pool| {
                load_all(&dir).map(|models| {
                    models
                        .into_iter()
                        .map(|(name, m)| (name, m.with_pool(pool.clone())))
                        .collect::<std::collections::BTreeMap<_, _>>()
                })
            });
        match loaded {
            Ok(models) => {
                let names: Vec<String> = models.keys().cloned().collect();
                loader_state.set_models(models);
                tracing::info!(?names, fit_threads, "models loaded; ready");
            }
            Err(e) => {
                let _ = failed_tx.send(e);
            }
        }
    });

    let drain_state = state.clone();
    let shutdown = async move {
        tokio::select! {
            _ = shutdown_signal() => {
                drain_state.ready.store(false, Ordering::SeqCst);
                tracing::info!("shutdown signal: draining in-flight requests");
                None
            }
            Ok(e) = failed_rx => Some(e),
        }
    };
    let (stop_tx, stop_rx) = tokio::sync::oneshot::channel::<Option<RegistryError>>();
    let (draining_tx, draining_rx) = tokio::sync::oneshot::channel::<()>();
    let server = axum::serve(listener, app).with_graceful_shutdown(async move {
        let outcome = shutdown.await;
        let _ = draining_tx.send(());
        let _ = stop_tx.send(outcome);
    });
    // In-flight requests get the request timeout (plus a second to write their answer) to
    // finish; a connection still open after that (a client stalled mid-request) does not keep
    // the process alive.
    let deadline = config.request_timeout + Duration::from_secs(1);
    let drain_limit = async move {
        if draining_rx.await.is_ok() {
            tokio::time::sleep(deadline).await;
        } else {
            std::future::pending::<()>().await;
        }
    };
    tokio::select! {
        served = server => served?,
        () = drain_limit => {
            tracing::warn!(?deadline, "drain deadline passed; closing the connections still open");
        }
    }
    match stop_rx.await {
        Ok(Some(e)) => Err(e.into()),
        _ => {
            tracing::info!("stopped");
            Ok(())
        }
    }
}

async fn shutdown_signal() {
    let ctrl_c = async {
        let _ = tokio::signal::ctrl_c().await;
    };
    #[cfg(unix)]
    let term = async {
        match tokio::signal::unix::signal(tokio::signal::unix::SignalKind::terminate()) {
            Ok(mut s) => {
                s.recv().await;
            }
            Err(_) => std::future::pending::<()>().await,
        }
    };
    #[cfg(not(unix))]
    let term = std::future::pending::<()>();
    tokio::select! {
        _ = ctrl_c => {},
        _ = term => {},
    }
}
