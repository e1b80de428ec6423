#!/bin/sh
# Entry point for one PX4 SITL (SIH) instance in the px4io/px4-sitl image, wired to the skyring ground station.
#
# PX4 SITL sends its MAVLink links to 127.0.0.1 by default, which stays inside this container. As PX4's own
# image does for Docker Desktop (px4-network.sh), point every `mavlink start` at the ground station instead:
# instance i then sends its API/offboard link to <ground station>:14540+i and its GCS link to :14550.
#
# Environment: PX4_INSTANCE (0, 1, ...: MAV_SYS_ID = instance + 1), SKYRING_GCS_HOST (the ground station's
# compose service name), PX4_HOME_LAT / PX4_HOME_LON / PX4_HOME_ALT (spawn point, degrees and metres AMSL),
# PX4_SIM_MODEL (sihsim_quadx, set by the image).
set -eu

: "${PX4_INSTANCE:=0}"
: "${SKYRING_GCS_HOST:=groundstation}"
PX4_PREFIX=/opt/px4
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

exec "$PX4_PREFIX/bin/px4" -i "$PX4_INSTANCE" "$@"
