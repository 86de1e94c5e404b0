#!/bin/busybox sh
# PID 1 of the kernel-driver tier's virtual machine (scripts/vm-test.sh builds the
# initramfs): mounts the kernel's file systems, loads the modules listed in
# /lib/modules/order (dependencies first), runs the cases of /cases.sh, which print
# `VMTEST PASS|FAIL name` lines on the serial console, and powers off.
/bin/busybox mkdir -p /proc /sys /dev /tmp /run
/bin/busybox --install -s /bin
export PATH=/usr/bin:/bin
export HOME=/tmp
# the shipped tables (fem-core/data) and hil-sim's scenarios
export TACTILE_DATA_DIR=/data
# plain log lines on the console
export NO_COLOR=1
mount -t proc proc /proc
mount -t sysfs sysfs /sys
mount -t devtmpfs devtmpfs /dev
mount -t tmpfs tmpfs /tmp
# the daemon's API listens on the loopback interface
ip link set lo up
# Kernel messages stay off the console (the results are parsed from it); they are kept in
# the ring buffer, and a failing case prints dmesg's tail.
dmesg -n 1

echo "VMTEST BOOT $(uname -r) $(nproc) cpus, uptime $(cut -d' ' -f1 /proc/uptime) s"
modules_ok=1
for m in $(cat /lib/modules/order); do
    args=
    case "$m" in
    # two device controllers: the controller's gadget on the first, the boot ROM's on the
    # second
    dummy_hcd) args="num=2" ;;
    # One instance with a video capture node (/dev/video0, one HDMI input) and a video
    # output node (/dev/video1, one HDMI output), no cropping, composing or scaling: the
    # output -> capture loop then passes frames through pixel for pixel.
    vivid) args="n_devs=1 node_types=0x101 num_inputs=1 input_types=0x3 num_outputs=1 output_types=0x1 ccs_cap_mode=0 ccs_out_mode=0" ;;
    # one loopback device, /dev/video10, as the workstation setup in docs/testing.md
    v4l2loopback) args="devices=1 video_nr=10 card_label=hil-sim exclusive_caps=1" ;;
    esac
    # shellcheck disable=SC2086 # the arguments are separate words
    if ! insmod "/lib/modules/$m.ko" $args 2>/tmp/insmod.log; then
        echo "VMTEST FAIL modules: insmod $m: $(cat /tmp/insmod.log)"
        modules_ok=0
    fi
done
mount -t configfs configfs /sys/kernel/config 2>/dev/null
if [ "$modules_ok" = 1 ]; then
    echo "VMTEST PASS modules: $(wc -l </lib/modules/order) kernel modules loaded"
fi

. /cases.sh

echo "VMTEST END uptime $(cut -d' ' -f1 /proc/uptime) s"
sync
poweroff -f
