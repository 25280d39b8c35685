# Builds both programs; the same image runs the coordinator and the workers.
# The base images are build arguments so that a host without Docker Hub can use local
# stand-ins (deploy/test-compose.sh makes them); the defaults are the Hub's images.
ARG BUILD_IMAGE=rust:1.95-bookworm
ARG RUNTIME_IMAGE=debian:bookworm-slim

FROM ${BUILD_IMAGE} AS build
WORKDIR /src
COPY . .
# Open Image Denoise for `render --denoise` (deploy/install-oidn.sh: from PyPI, with Debian's
# pip if the image lacks it); the coordinator finds it at /src/.oidn/lib, its run path.
RUN deploy/install-oidn.sh \
    && cargo build --release --locked -p coordinator --features denoise -p worker

FROM ${RUNTIME_IMAGE}
RUN useradd --system --create-home --home-dir /var/lib/photonfarm photonfarm \
    && mkdir -p /data && chown photonfarm /data
COPY --from=build /src/target/release/coordinator /src/target/release/worker /usr/local/bin/
COPY --from=build /src/.oidn /src/.oidn
COPY --from=build /src/scenes /usr/share/photonfarm/scenes
USER photonfarm
EXPOSE 8080
CMD ["coordinator", "serve", "--bind", "0.0.0.0:8080", "--data", "/data"]
