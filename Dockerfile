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
 && DEBIAN_FRONTEND=noninteractive apt-get install -y --no-install-recommends liblapacke \
 && rm -rf /var/lib/apt/lists/* \
 && useradd --system --create-home subdivd
COPY --from=build /src/build/sdlevel /usr/local/bin/sdlevel
COPY --from=build /src/examples /home/subdivd/examples
USER subdivd
WORKDIR /home/subdivd
CMD ["sdlevel", "--stats", "-l", "3", "examples/mixed.txt"]
