# syntax=docker/dockerfile:1
# Build stage: the official Rust image, same toolchain as development.
FROM rust:1.95-bookworm AS build
WORKDIR /src
COPY Cargo.toml Cargo.lock ./
# Cargo.toml declares [[bench]] core (benches/core.rs): without it cargo cannot parse the manifest,
# even to build only the server binary.
COPY benches ./benches
COPY src ./src
COPY openapi.yaml ./
# Portable code: no target-cpu=native, so the image runs on any x86-64 host.
RUN cargo build --release --locked --bin multifit-server

# Runtime stage: a small Debian image with the binary and the shipped models.
FROM debian:bookworm-slim
# DL3008 (pin apt versions) ignored: bookworm's security archive replaces package versions, so a
# pinned version stops resolving and the image stops building; the base image tag is the pin.
# hadolint ignore=DL3008
RUN apt-get update \
    && apt-get install -y --no-install-recommends ca-certificates curl \
    && rm -rf /var/lib/apt/lists/* \
    && groupadd --system --gid 10001 multifit \
    && useradd --system --uid 10001 --gid multifit --no-create-home multifit
WORKDIR /app
COPY --from=build /src/target/release/multifit-server /usr/local/bin/multifit-server
COPY models ./models
# Numeric, so Kubernetes' runAsNonRoot can check it (deploy/kubernetes.yaml runs as 10001).
USER 10001:10001
ENV MULTIFIT_ADDR=0.0.0.0:8080 \
    MULTIFIT_MODELS=/app/models \
    MULTIFIT_LOG_FORMAT=json
EXPOSE 8080
HEALTHCHECK --interval=10s --timeout=3s --start-period=10s --retries=3 \
    CMD ["/bin/sh", "-c", "curl -fsS http://127.0.0.1:8080/health/ready || exit 1"]
ENTRYPOINT ["/usr/local/bin/multifit-server"]
