#!/bin/sh
# Entry point of one PX4 SITL (SIH) container (docker/px4-sitl.Dockerfile), wired to the skyring ground station.
#
# PX4 SITL sends its MAVLink links to 127.0.0.1, which stays inside this container. So every `mavlink start`
# of PX4's startup file gets the ground station as its partner (-t): instance i then sends its API/offboard
# link to <ground station>:14540+i and its GCS link to <ground station>:14550 (PX4 binds its own ports on
# every interface, so the answers come back).
#
# Environment: PX4_INSTANCE (0, 1, ...: MAV_SYS_ID = instance + 1), SKYRING_GCS_HOST (the ground station's
# compose service name), PX4_HOME_LAT / PX4_HOME_LON / PX4_HOME_ALT (spawn point, degrees and metres AMSL),
# PX4_SIM_MODEL / PX4_SYS_AUTOSTART (sihsim_quadx / 10040, set by the image), PX4_PREFIX (/opt/px4).
set -eu

: "${PX4_INSTANCE:=0}"
: "${SKYRING_GCS_HOST:=groundstation}"
: "${PX4_PREFIX:=/opt/px4}"
: "${PX4_WORK:=/var/lib/px4}"
RC_MAVLINK="$PX4_PREFIX/etc/init.d-posix/px4-rc.mavlink"

tries=0
GCS_IP=""
while [ -z "$GCS_IP" ]; do
    GCS_IP=$(getent ahostsv4 "$SKYRING_GCS_HOST" 2>/dev/null | awk '/STREAM/ {print $1; exit}')
    if [ -z "$GCS_IP" ]; then
        tries=$((tries + 1))
        if [ "$tries" -gt 60 ]; then
            echo "px4-sitl-entrypoint: cannot resolve the ground station '$SKYRING_GCS_HOST'" >&2
            exit 1
        fi
        sleep 1
    fi
done

# Replace an existing target too, so a container restart is safe.
sed -i -E "s/(mavlink start -x)( -t [^ ]+)? -u/\1 -t $GCS_IP -u/g" "$RC_MAVLINK"
echo "px4-sitl-entrypoint: instance $PX4_INSTANCE -> ground station $SKYRING_GCS_HOST ($GCS_IP)," \
     "home ${PX4_HOME_LAT:-default} ${PX4_HOME_LON:-default} ${PX4_HOME_ALT:-default}"

# Daemon mode (no PX4 shell); parameters persist in the instance's working directory.
mkdir -p "$PX4_WORK/$PX4_INSTANCE"
exec "$PX4_PREFIX/bin/px4" -d "$PX4_PREFIX/etc" -i "$PX4_INSTANCE" -w "$PX4_WORK/$PX4_INSTANCE" "$@"
