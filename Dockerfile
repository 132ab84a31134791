# Navig8 SITL in a container: the flight controller and the physics bridge in real time.
#
#   docker build -t navig8-sitl .
#   docker run --rm -it -p 18570:18570/udp -p 14580:14580/udp \
#       -e NAVIG8_GCS_HOST=host.docker.internal --add-host=host.docker.internal:host-gateway navig8-sitl
#
# The FC sends its telemetry to $NAVIG8_GCS_HOST:14550 (QGroundControl, MAVProxy) and :14540 (MAVSDK) on
# the host, whose replies come back through Docker's NAT; a ground station may also talk first to the FC's
# own ports 18570 (GCS link) and 14580 (API link), published above. Do not publish 14550/14540: those are
# the host's ground stations' ports, and docker-proxy would take them. On Linux `--network host` with
# NAVIG8_GCS_HOST=127.0.0.1 is the simplest alternative.
# The steps below are the ones `make` runs (venv, editable install of the project with its pinned
# dependency ranges, MAVProxy lean), so what CI tests is what the image runs.
FROM python:3.11-slim

ENV PYTHONDONTWRITEBYTECODE=1 PIP_NO_CACHE_DIR=1 NAVIG8_CACHE_DIR=/opt/navig8/cache \
    NAVIG8_GCS_HOST=host.docker.internal
RUN apt-get update && apt-get install -y --no-install-recommends make && rm -rf /var/lib/apt/lists/*
WORKDIR /opt/navig8
COPY . .
# Same as `make install`: .venv with the project and its test extras, then warm the numba and dialect caches.
RUN make install && .venv/bin/python -c "from navig8_fc.mavlink import dialect; dialect.load()" \
    && .venv/bin/navig8-sim --scenario hover --duration 0.1 --log /tmp/warm.mcap >/dev/null && rm -f /tmp/warm.mcap
EXPOSE 18570/udp 14580/udp
CMD ["sh", "-c", ".venv/bin/navig8-sitl --speed 1 --bind-host 0.0.0.0 --gcs-host \"$NAVIG8_GCS_HOST\" --log-dir /opt/navig8/logs --state-dir /opt/navig8/state"]
