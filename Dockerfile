FROM rust:1-bookworm AS build
WORKDIR /src
COPY . .
RUN cargo build --release --locked --bin vtfarm

FROM debian:bookworm-slim
COPY --from=build /src/target/release/vtfarm /usr/local/bin/vtfarm
ENTRYPOINT ["vtfarm"]
