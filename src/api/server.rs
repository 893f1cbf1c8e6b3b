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
use crate::registry::{RegistryError, load_all};
use crate::threads::Threads;

/// Log output format.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, clap::ValueEnum)]
#[serde(rename_all = "snake_case")]
pub enum LogFormat {
    Text,
    Json,
}

/// A server configuration as given; [`ServerConfig::validate`] checks it into the
/// [`ValidServerConfig`] that [`serve`] takes.
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

/// A [`ServerConfig`] whose ranges are checked; only [`ServerConfig::validate`] makes one.
#[derive(Debug, Clone, Serialize)]
#[serde(transparent)]
pub struct ValidServerConfig(ServerConfig);

impl std::ops::Deref for ValidServerConfig {
    type Target = ServerConfig;
    fn deref(&self) -> &ServerConfig {
        &self.0
    }
}

/// Why a configuration is refused.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum ConfigError {
    #[error("invalid configuration: body limit must be at least 1024 bytes, got {0}")]
    BodyLimit(usize),
    #[error("invalid configuration: max points must be at least 2, got {0}")]
    MaxPoints(usize),
    #[error("invalid configuration: max frames must be at least 2, got {0}")]
    MaxFrames(usize),
    #[error("invalid configuration: max k_max must be at least 1")]
    MaxKMax,
    #[error("invalid configuration: max batch must be at least 1")]
    MaxBatch,
    #[error("invalid configuration: workers must be at least 1")]
    Workers,
    #[error("invalid configuration: fit threads must be at least 1")]
    FitThreads,
    #[error("invalid configuration: request timeout must be positive")]
    RequestTimeout,
}

/// Why the server could not start or stopped with an error.
#[derive(Debug, thiserror::Error)]
pub enum ServerError {
    #[error("cannot listen on {addr}: {source}")]
    Bind {
        addr: SocketAddr,
        source: std::io::Error,
    },
    #[error("cannot load models: {0}")]
    Models(#[from] RegistryError),
    #[error("cannot start {count} fit threads: {source}")]
    Threads {
        count: usize,
        source: rayon::ThreadPoolBuildError,
    },
    #[error("server failed: {0}")]
    Io(#[from] std::io::Error),
}

impl ServerConfig {
    /// Checks ranges.
    pub fn validate(self) -> Result<ValidServerConfig, ConfigError> {
        let limits = &self.limits;
        let error = if self.body_limit < 1024 {
            Some(ConfigError::BodyLimit(self.body_limit))
        } else if limits.max_points < 2 {
            Some(ConfigError::MaxPoints(limits.max_points))
        } else if limits.max_frames < 2 {
            Some(ConfigError::MaxFrames(limits.max_frames))
        } else if limits.max_k_max == 0 {
            Some(ConfigError::MaxKMax)
        } else if limits.max_batch == 0 {
            Some(ConfigError::MaxBatch)
        } else if self.workers == 0 {
            Some(ConfigError::Workers)
        } else if self.fit_threads == 0 {
            Some(ConfigError::FitThreads)
        } else if self.request_timeout.is_zero() {
            Some(ConfigError::RequestTimeout)
        } else {
            None
        };
        match error {
            Some(e) => Err(e),
            None => Ok(ValidServerConfig(self)),
        }
    }
}

/// Binds, loads every model (the service answers 503 on /health/ready until then), serves until
/// SIGTERM or Ctrl-C, then stops accepting, finishes in-flight requests and returns.
/// `on_bound` receives the bound address (useful with port 0).
pub async fn serve(
    config: ValidServerConfig,
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

    let (failed_tx, failed_rx) = tokio::sync::oneshot::channel::<ServerError>();
    let loader_state = state.clone();
    let dir = config.models.clone();
    let fit_threads = config.fit_threads;
    tokio::task::spawn_blocking(move || {
        let loaded = Threads::new(fit_threads)
            .map_err(|source| ServerError::Threads {
                count: fit_threads,
                source,
            })
            .and_then(|pool| {
                let models = load_all(&dir)?;
                Ok(models
                    .into_iter()
                    .map(|(name, m)| (name, m.with_pool(pool.clone())))
                    .collect::<std::collections::BTreeMap<_, _>>())
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
    let (stop_tx, stop_rx) = tokio::sync::oneshot::channel::<Option<ServerError>>();
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
        Ok(Some(e)) => Err(e),
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
