# supertoroid fitting service: a Rust builder and a slim Debian runtime with the Vulkan
# loader only. On a host without a GPU the service fits on the CPU (`auto` never picks a
# software adapter, so lavapipe would be 400 MB of unused LLVM); on an NVIDIA host run with
# --gpus all and NVIDIA_DRIVER_CAPABILITIES=compute,graphics,utility (see the README) and
# the toolkit mounts NVIDIA's Vulkan driver. `--build-arg LAVAPIPE=1` adds Mesa's lavapipe
# for running the GPU code path on the CPU (SUPERTOROID_BACKEND=gpu without a GPU).
#
#   docker build -t supertoroid .
#   docker run --rm -p 8080:8080 supertoroid
#
# Offline builds: the base images must be present locally (docker build --pull=false);
# run `cargo vendor` in the checkout first and the crates come from ./vendor, not the
# network.

FROM rust:1-bookworm AS build
WORKDIR /src
# The crates first, in their own layer: a change to the sources rebuilds only this crate.
COPY Cargo.toml Cargo.lock ./
COPY vendo[r] vendor/
COPY scripts/placeholder-sources /usr/local/bin/
RUN if [ -d vendor ]; then \
        mkdir -p .cargo && \
        printf '[source.crates-io]\nreplace-with = "vendored"\n[source.vendored]\ndirectory = "vendor"\n' > .cargo/config.toml; \
    fi && \
    placeholder-sources && \
    cargo build --release --locked --bin supertoroid && \
    rm -rf src benches
COPY src src/
COPY shaders shaders/
COPY assets assets/
COPY benches benches/
# newer than the placeholder build, so cargo rebuilds this crate from the real sources
RUN touch src/lib.rs src/main.rs && \
    cargo build --release --locked --bin supertoroid && \
    strip target/release/supertoroid

FROM debian:bookworm-slim
ARG LAVAPIPE=0
RUN apt-get update && \
    apt-get install -y --no-install-recommends libvulkan1 \
        $(if [ "$LAVAPIPE" = 1 ]; then echo mesa-vulkan-drivers; fi) && \
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
