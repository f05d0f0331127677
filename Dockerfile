# subdivd on Debian 12. The package list is tools/packages.txt, the same one .ci/run installs.
FROM debian:12 AS build
WORKDIR /src
COPY tools/packages.txt tools/packages.txt
RUN apt-get update \
 && DEBIAN_FRONTEND=noninteractive apt-get install -y --no-install-recommends make \
      $(grep -v '^#' tools/packages.txt | tr '\n' ' ') \
 && rm -rf /var/lib/apt/lists/*
COPY . .
RUN make all

FROM debian:12-slim
RUN apt-get update \
 && DEBIAN_FRONTEND=noninteractive apt-get install -y --no-install-recommends \
      liblapacke libjansson4 libmicrohttpd12 \
 && rm -rf /var/lib/apt/lists/* \
 && useradd --system --create-home subdivd
COPY --from=build /src/build/subdivd /usr/local/bin/subdivd
COPY --from=build /src/build/sdlevel /usr/local/bin/sdlevel
COPY --from=build /src/examples /home/subdivd/examples
USER subdivd
WORKDIR /home/subdivd
EXPOSE 8080
# Listen on all interfaces inside the container; publish with `docker run -p 8080:8080`.
CMD ["subdivd", "--listen", "0.0.0.0", "--port", "8080"]
