# syntax=docker/dockerfile:1
# Build stage: the official Rust image, same toolchain as development.
FROM rust:1.95-bookworm AS build
WORKDIR /src
COPY Cargo.toml Cargo.lock ./
COPY src ./src
COPY openapi.yaml ./
# Portable code: no target-cpu=native, so the image runs on any x86-64 host.
RUN cargo build --release --locked --bin multifit-server

# Runtime stage: a small Debian image with the binary and the shipped models.
FROM debian:bookworm-slim
RUN apt-get update \
    && apt-get install -y --no-install-recommends ca-certificates curl \
    && rm -rf /var/lib/apt/lists/* \
    && useradd --system --uid 10001 --no-create-home multifit
WORKDIR /app
COPY --from=build /src/target/release/multifit-server /usr/local/bin/multifit-server
COPY models ./models
USER multifit
ENV MULTIFIT_ADDR=0.0.0.0:8080 \
    MULTIFIT_MODELS=/app/models \
    MULTIFIT_LOG_FORMAT=json
EXPOSE 8080
HEALTHCHECK --interval=10s --timeout=3s --start-period=10s --retries=3 \
    CMD curl -fsS http://127.0.0.1:8080/health/ready || exit 1
ENTRYPOINT ["/usr/local/bin/multifit-server"]
