#!/bin/sh
# The container's entry point: sizes lavapipe's thread pool to the container's CPU limit
# (cgroup v2 `cpu.max`, else v1 quota/period, else the CPUs visible) so that software
# rendering does not oversubscribe a limited container, then becomes penumbra (PID 1 gets
# SIGTERM and shuts down gracefully).
set -eu

cpus=""
if [ -r /sys/fs/cgroup/cpu.max ]; then
    read -r quota period < /sys/fs/cgroup/cpu.max
    if [ "$quota" != "max" ]; then
        cpus=$(( (quota + period - 1) / period ))
    fi
elif [ -r /sys/fs/cgroup/cpu/cpu.cfs_quota_us ] && [ -r /sys/fs/cgroup/cpu/cpu.cfs_period_us ]; then
    quota=$(cat /sys/fs/cgroup/cpu/cpu.cfs_quota_us)
    period=$(cat /sys/fs/cgroup/cpu/cpu.cfs_period_us)
    if [ "$quota" -gt 0 ]; then
        cpus=$(( (quota + period - 1) / period ))
    fi
fi
if [ -z "$cpus" ]; then
    cpus=$(nproc)
fi
if [ "$cpus" -lt 1 ]; then
    cpus=1
fi
export LP_NUM_THREADS="${LP_NUM_THREADS:-$cpus}"
exec /usr/local/bin/penumbra "$@"
