#!/bin/sh
# Entry point of the skyring ground-station container: runs `skyring "$@"`.
#
# SKYRING_PX4_SITL=N (set by compose.yaml) turns `serve` into `serve --px4 udpin://0.0.0.0:14540 ...` for N
# PX4 SITL containers, instance i sending to UDP 14540+i of this container; SKYRING_ORIGIN=lat,lon,alt sets
# the team frame's origin. Anything given on the command line is passed through unchanged.
set -eu

if [ "${1:-}" = "serve" ] && [ -n "${SKYRING_PX4_SITL:-}" ]; then
    shift
    urls=""
    i=0
    while [ "$i" -lt "$SKYRING_PX4_SITL" ]; do
        port=$((14540 + i))
        [ "$i" -gt 9 ] && port=14549
        urls="${urls:+$urls,}udpin://0.0.0.0:$port"
        i=$((i + 1))
    done
    set -- serve --px4 "$urls" ${SKYRING_ORIGIN:+--origin "$SKYRING_ORIGIN"} "$@"
fi

exec skyring "$@"
