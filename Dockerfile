# subdivd on Debian 12, in two stages.
#   build:   Debian 12 with exactly the packages of tools/packages.txt (the same apt-get line as
#            .ci/run, checked by tests/python/test_dockerfile.py), then the daemon, its TetGen
#            helper, sdlevel and subdivd-mpi (docs/BATCH.md section 7); the helper proves TetGen works (--selftest) before anything ships.
#   runtime: debian:12-slim with only the runtime libraries, as a non-root user.
# docker build -t subdivd . && docker run -p 8080:8080 subdivd
FROM debian:12 AS build
WORKDIR /src
COPY tools/packages.txt tools/apt-packages.sh tools/
RUN apt-get update \
 && DEBIAN_FRONTEND=noninteractive apt-get install -y --no-install-recommends make $(sh tools/apt-packages.sh | tr '\n' ' ') \
 && rm -rf /var/lib/apt/lists/*
COPY . .
RUN make build/subdivd build/subdivd-tetgen build/sdlevel build/subdivd-mpi \
 && build/subdivd-tetgen --selftest

FROM debian:12-slim AS runtime
# libjansson4, libmicrohttpd12, liblapacke, zlib1g, libsqlite3-0, libnettle8, libhiredis0.14:
# subdivd; libtet1.5, libstdc++6: subdivd-tetgen; libmetis5 and openmpi-bin (mpirun and
# libopenmpi3): subdivd-mpi, run as `mpirun -n N subdivd-mpi refine ...`
RUN apt-get update \
 && DEBIAN_FRONTEND=noninteractive apt-get install -y --no-install-recommends \
      libjansson4 libmicrohttpd12 liblapacke zlib1g libsqlite3-0 libnettle8 libhiredis0.14 \
      libtet1.5 libstdc++6 libmetis5 openmpi-bin \
 && rm -rf /var/lib/apt/lists/* \
 && useradd --system --uid 10001 --create-home --home-dir /home/subdivd subdivd \
 && mkdir -p /data && chown subdivd /data
# subdivd finds its TetGen helper beside itself
COPY --from=build /src/build/subdivd /src/build/subdivd-tetgen /src/build/sdlevel \
     /src/build/subdivd-mpi /usr/local/bin/
COPY --from=build /src/examples /home/subdivd/examples
USER subdivd
WORKDIR /home/subdivd
EXPOSE 8080
# the image has no curl: the daemon binary itself is the probe (GET /healthz, exit 0 on 200)
HEALTHCHECK --interval=30s --timeout=5s --start-period=5s --retries=3 \
    CMD ["subdivd", "--healthcheck", "http://127.0.0.1:8080/healthz"]
# Sessions are kept in the volume /data (SQLite): they survive the container.
VOLUME ["/data"]
# Listen on all interfaces inside the container; publish with `docker run -p 8080:8080`.
CMD ["subdivd", "--listen", "0.0.0.0", "--port", "8080", "--store", "sqlite:/data/sessions.db"]
