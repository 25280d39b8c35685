# Builds both programs; the same image runs the coordinator and the workers.
FROM rust:1.95-bookworm AS build
WORKDIR /src
COPY . .
RUN cargo build --release --locked -p coordinator -p worker

FROM debian:bookworm-slim
RUN useradd --system --create-home --home-dir /var/lib/photonfarm photonfarm \
    && mkdir -p /data && chown photonfarm /data
COPY --from=build /src/target/release/coordinator /src/target/release/worker /usr/local/bin/
COPY --from=build /src/scenes /usr/share/photonfarm/scenes
USER photonfarm
EXPOSE 8080
CMD ["coordinator", "serve", "--bind", "0.0.0.0:8080", "--data", "/data"]
