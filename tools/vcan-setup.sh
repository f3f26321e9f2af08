#!/bin/sh
# Create virtual SocketCAN interfaces on a Linux host (needs root and a kernel with CAN):
#   sudo tools/vcan-setup.sh vcan0 vcan1
# A vcan takes CAN FD frames (its MTU is 72); a name ending in +classic gets the classical
# MTU 16, where the kernel refuses an FD frame: sudo tools/vcan-setup.sh vcancc0+classic
# Then run hil on them, e.g.  hil sim bus_config/ur3.yaml --interface socketcan \
#   --channel arm=vcan0 --channel wrist=vcan1
# Where the kernel has no CAN (containers, this project's CI), use tools/uml_run.py.
set -eu
[ "$#" -gt 0 ] || set -- vcan0
modprobe vcan 2>/dev/null || {
    echo "vcan-setup: cannot load the vcan module (no CAN in this kernel?)" >&2
    echo "            run inside User-Mode Linux instead: tools/uml_run.py --vcan $1 -- ..." >&2
    exit 1
}
for arg in "$@"; do
    name=${arg%+classic}
    if ! ip link show "$name" >/dev/null 2>&1; then
        ip link add dev "$name" type vcan
    fi
    if [ "$name" != "$arg" ]; then
        ip link set down "$name"
        ip link set "$name" mtu 16
    fi
    ip link set up "$name"
    echo "vcan-setup: $name is up (mtu $(cat /sys/class/net/$name/mtu))"
done
