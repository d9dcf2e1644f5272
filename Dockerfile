# tempokey: bookworm build stage -> slim runtime stage.
#   podman build -t tempokey .            (or --build-arg BASE=<local bookworm image>)
ARG BASE=debian:bookworm

FROM ${BASE} AS build
WORKDIR /src
COPY deploy/install-deps.sh deploy/install-deps.sh
RUN deploy/install-deps.sh --build
COPY . .
RUN cmake -S . -B /build -G Ninja -DCMAKE_BUILD_TYPE=Release \
      -DTEMPOKEY_BUILD_TESTS=OFF -DTEMPOKEY_BUILD_BENCH=OFF \
 && ninja -C /build tempokey-server tempokey \
 && strip /build/server/tempokey-server /build/client/tempokey

FROM ${BASE} AS runtime
COPY deploy/install-deps.sh /usr/local/lib/tempokey/install-deps.sh
RUN /usr/local/lib/tempokey/install-deps.sh --runtime \
 && rm -rf /var/lib/apt/lists/* \
 && useradd --system --uid 10001 --no-create-home --shell /usr/sbin/nologin tempokey
COPY --from=build /build/server/tempokey-server /build/client/tempokey /usr/local/bin/
# The studio page (served with --http_address; the binary finds it in ../share/tempokey/web).
COPY --from=build /src/web /usr/local/share/tempokey/web
USER 10001
EXPOSE 50051 9464 8080
STOPSIGNAL SIGTERM
ENTRYPOINT ["/usr/local/bin/tempokey-server", "--address", "0.0.0.0:50051", "--allow_insecure_remote", "--metrics_address", "0.0.0.0:9464"]
