# The vtfarm image, built from source with a registry's Rust image (multi-stage):
#   docker build -t vtfarm .
# Without a registry, contrib/docker/Dockerfile.prebuilt packs a binary built on the host
# instead (see README, "Containers"); keep the runtime stage the same in both.
FROM rust:1-bookworm AS build
WORKDIR /src
COPY . .
RUN cargo build --release --locked --bin vtfarm

FROM debian:bookworm-slim
# An unprivileged user; /state (the master's key, certificate and cluster.toml) and /out (frames)
# are volume mount points owned by it, so named volumes start out writable.
RUN useradd --system --create-home --uid 10001 vtfarm \
    && mkdir /state /out && chown vtfarm:vtfarm /state /out
COPY --from=build /src/target/release/vtfarm /usr/local/bin/vtfarm
USER vtfarm
ENTRYPOINT ["vtfarm"]
