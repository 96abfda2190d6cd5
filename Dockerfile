# supertoroid fitting service: a Rust builder and a slim Debian runtime with Mesa's
# lavapipe (Vulkan on the CPU), so the GPU code path works on any host; on an NVIDIA
# host run with --gpus all (see the README) and the real GPU is picked instead.
#
#   docker build -t supertoroid .
#   docker run --rm -p 8080:8080 supertoroid
#
# Offline builds: the base images must be present locally (docker build --pull=false);
# run `cargo vendor` in the checkout first and the crates come from ./vendor, not the
# network.

FROM rust:1-bookworm AS build
WORKDIR /src
COPY . .
RUN if [ -d vendor ]; then \
        mkdir -p .cargo && \
        printf '[source.crates-io]\nreplace-with = "vendored"\n[source.vendored]\ndirectory = "vendor"\n' > .cargo/config.toml; \
    fi && \
    cargo build --release --locked --bin supertoroid && \
    strip target/release/supertoroid

FROM debian:bookworm-slim
RUN apt-get update && \
    apt-get install -y --no-install-recommends mesa-vulkan-drivers libvulkan1 && \
    rm -rf /var/lib/apt/lists/* && \
    useradd --system --uid 10001 --no-create-home supertoroid
COPY --from=build /src/target/release/supertoroid /usr/local/bin/supertoroid
USER 10001
ENV SUPERTOROID_BIND=0.0.0.0:8080 \
    SUPERTOROID_LOG_FORMAT=json \
    WGPU_BACKEND=vulkan \
    XDG_RUNTIME_DIR=/tmp
EXPOSE 8080
# bash's /dev/tcp: no curl in the image
HEALTHCHECK --interval=10s --timeout=3s --start-period=10s --retries=3 \
    CMD ["bash", "-c", "exec 3<>/dev/tcp/127.0.0.1/8080 && printf 'GET /healthz HTTP/1.0\\r\\n\\r\\n' >&3 && head -n1 <&3 | grep -q ' 200 '"]
ENTRYPOINT ["supertoroid"]
CMD ["serve"]
