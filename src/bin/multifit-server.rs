//! multifit-server: serves the models in `models/` over HTTP/JSON.
#![forbid(unsafe_code)]

use std::net::SocketAddr;
use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Duration;

use clap::Parser;
use multifit::api::{Limits, LogFormat, ServerConfig, serve};

/// Multi-model, multi-type fitting as an HTTP/JSON service (see openapi.yaml).
#[derive(Parser, Debug)]
#[command(version, about)]
struct Args {
    /// Address to listen on.
    #[arg(long, env = "MULTIFIT_ADDR", default_value = "127.0.0.1:8080")]
    addr: SocketAddr,
    /// Directory holding one sub-directory per model (model.json + weights.safetensors).
    #[arg(long, env = "MULTIFIT_MODELS", default_value = "models")]
    models: PathBuf,
    /// Largest request body in bytes.
    #[arg(long, env = "MULTIFIT_BODY_LIMIT", default_value_t = 64 * 1024 * 1024)]
    body_limit: usize,
    /// Most points (rows) in one fit.
    #[arg(long, env = "MULTIFIT_MAX_POINTS", default_value_t = 20_000)]
    max_points: usize,
    /// Most frames per trajectory.
    #[arg(long, env = "MULTIFIT_MAX_FRAMES", default_value_t = 500)]
    max_frames: usize,
    /// Largest k_max a request may ask for.
    #[arg(long, env = "MULTIFIT_MAX_K_MAX", default_value_t = 20)]
    max_k_max: usize,
    /// Most fits in one batch request.
    #[arg(long, env = "MULTIFIT_MAX_BATCH", default_value_t = 32)]
    max_batch: usize,
    /// Fits that may wait for a worker before new ones get 429.
    #[arg(long, env = "MULTIFIT_QUEUE_CAPACITY", default_value_t = 64)]
    queue_capacity: usize,
    /// Request timeout in milliseconds (queueing included); past it, 503.
    #[arg(long, env = "MULTIFIT_REQUEST_TIMEOUT_MS", default_value_t = 30_000)]
    request_timeout_ms: u64,
    /// Fits computed at once (default: available parallelism, which respects cgroup limits).
    #[arg(long, env = "MULTIFIT_WORKERS")]
    workers: Option<usize>,
    /// Threads of the one pool all fits compute on (default: available parallelism). A fit
    /// alone uses every thread; fits running at once share them. With 1 there is no pool: each
    /// fit runs on its own worker thread, --workers of them at once.
    #[arg(long, env = "MULTIFIT_FIT_THREADS")]
    fit_threads: Option<usize>,
    /// Log format.
    #[arg(long, env = "MULTIFIT_LOG_FORMAT", value_enum, default_value = "text")]
    log_format: LogFormat,
}

impl Args {
    fn into_config(self) -> ServerConfig {
        let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
        let workers = self.workers.unwrap_or(cores);
        ServerConfig {
            addr: self.addr,
            models: self.models,
            body_limit: self.body_limit,
            limits: Limits {
                max_points: self.max_points,
                max_frames: self.max_frames,
                max_k_max: self.max_k_max,
                max_batch: self.max_batch,
            },
            queue_capacity: self.queue_capacity,
            request_timeout: Duration::from_millis(self.request_timeout_ms),
            workers,
            fit_threads: self.fit_threads.unwrap_or(cores),
            log_format: self.log_format,
        }
    }
}

fn init_logging(format: LogFormat) {
    let filter = tracing_subscriber::EnvFilter::try_from_default_env()
        .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new("info,tower_http=info"));
    use std::io::IsTerminal;
    let builder = tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_writer(std::io::stderr)
        .with_ansi(std::io::stderr().is_terminal());
    match format {
        LogFormat::Text => builder.init(),
        LogFormat::Json => builder.json().init(),
    }
}

fn main() -> ExitCode {
    let args = Args::parse();
    init_logging(args.log_format);
    let config = match args.into_config().validate() {
        Ok(c) => c,
        Err(e) => {
            tracing::error!("{e}");
            return ExitCode::from(2);
        }
    };
    tracing::info!(config = %serde_json::to_string(&config).unwrap_or_default(), "effective configuration");
    let runtime = match tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()
    {
        Ok(r) => r,
        Err(e) => {
            tracing::error!("cannot start the async runtime: {e}");
            return ExitCode::FAILURE;
        }
    };
    // The bound address on stdout, one line (scripts and tests read it when --addr has port 0).
    let announce = |addr| {
        use std::io::Write;
        println!("multifit-server listening on http://{addr}");
        let _ = std::io::stdout().flush();
    };
    match runtime.block_on(serve(config, announce)) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            tracing::error!("{e}");
            ExitCode::FAILURE
        }
    }
}
