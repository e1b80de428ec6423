# syntax=docker/dockerfile:1
# PX4 v1.16.0 SITL with SIH (PX4's built-in physics, no Gazebo), built from the pinned release tag: the PX4
# skyring is tested against (make test-px4). PX4 publishes px4io/px4-sitl images only from v1.17 on, so the
# compose file builds this one. The build is the one docs/px4.md describes: the release tag at its commit,
# only the submodules SITL needs, and the two modules that would need further submodules switched off.
#
# Build from docker/:   docker build -f px4-sitl.Dockerfile -t skyring-px4-sitl:v1.16.0 .
# (compose.yaml does this). Takes 10-20 minutes on two cores; the image is about 150 MB.

ARG PX4_TAG=v1.16.0
ARG PX4_COMMIT=6ea3539157ca358c70a515878b77077af7d4611d

FROM debian:bookworm AS build
ARG PX4_TAG
ARG PX4_COMMIT
RUN apt-get update \
    && apt-get install -y --no-install-recommends ca-certificates git cmake ninja-build g++ make python3 \
       python3-venv \
    && rm -rf /var/lib/apt/lists/*
RUN git clone --depth 1 --branch "$PX4_TAG" https://github.com/PX4/PX4-Autopilot.git /src/PX4 \
    && test "$(git -C /src/PX4 rev-parse HEAD)" = "$PX4_COMMIT"
WORKDIR /src/PX4
# The submodules SITL needs, at the commits the tag pins.
RUN git submodule update --init --depth 1 src/modules/mavlink/mavlink src/drivers/gps/devices \
       src/lib/events/libevents src/lib/heatshrink/heatshrink \
    && git -C src/modules/mavlink/mavlink submodule update --init --depth 1 pymavlink
# The gyro FFT and the uXRCE-DDS client need further submodules and tools; the SIH quadrotor uses neither.
RUN for opt in CONFIG_MODULES_GYRO_FFT CONFIG_MODULES_UXRCE_DDS_CLIENT; do \
        board=boards/px4/sitl/default.px4board; \
        if grep -q "^$opt=" "$board"; then sed -i "s/^$opt=.*/$opt=n/" "$board"; else echo "$opt=n" >> "$board"; fi; \
    done
# PX4's code generators (empy must be 3.x).
RUN python3 -m venv /venv \
    && /venv/bin/pip install --no-cache-dir empy==3.3.4 pyyaml jinja2 jsonschema kconfiglib pyros-genmsg \
       packaging future numpy lxml toml psutil pyserial pygments setuptools wheel six cerberus argcomplete
ENV PATH=/venv/bin:$PATH \
    GIT_SUBMODULES_ARE_EVIL=1
RUN cmake -S . -B build/px4_sitl_default -G Ninja -DCONFIG=px4_sitl_default \
    && cmake --build build/px4_sitl_default

FROM debian:bookworm-slim
ARG PX4_TAG
LABEL org.opencontainers.image.title="PX4 SITL (SIH) for skyring" \
      org.opencontainers.image.version="$PX4_TAG"
# bin/ holds the px4 binary and its px4-<module> links; etc/ the startup scripts and airframes.
COPY --from=build /src/PX4/build/px4_sitl_default/bin /opt/px4/bin
COPY --from=build /src/PX4/build/px4_sitl_default/etc /opt/px4/etc
COPY --chmod=755 px4-sitl-entrypoint.sh /usr/local/bin/px4-sitl-entrypoint.sh
ENV PATH=/opt/px4/bin:$PATH \
    PX4_SIM_MODEL=sihsim_quadx \
    PX4_SIMULATOR=sihsim \
    PX4_SYS_AUTOSTART=10040
WORKDIR /var/lib/px4
ENTRYPOINT ["/usr/local/bin/px4-sitl-entrypoint.sh"]
