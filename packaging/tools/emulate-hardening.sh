#!/bin/sh
# Runs the installed pipeline under an emulation of linetrack.service's sandbox, for a
# machine without systemd as PID 1 (a container): a private mount namespace with / read-only
# (ProtectSystem=strict), /tmp and /home private and empty (PrivateTmp=, ProtectHome=), a
# writable state folder and runtime folder (StateDirectory=, RuntimeDirectory=), no new
# privileges, as an unprivileged user (User=); /dev, and so /dev/shm, left as it is.
# Passes when a run of the installed binaries completes through shared memory.
#
# usage (as root): emulate-hardening.sh ROOT WORK
#   ROOT  an unpacked package (dpkg-deb -x linetrack_*.deb ROOT)
#   WORK  an empty scratch folder outside /tmp and /home, short (iceoryx2's socket paths)
set -eu
root=$(realpath "$1")
work=$(realpath "$2")
user=nobody
mkdir -p "$work/state" "$work/run"
chown "$user" "$work/state" "$work/run"
chmod 0700 "$work/run"
unshare -m sh -eu -c "
mount --make-rprivate /
mount --bind '$work/state' '$work/state'
mount --bind '$work/run' '$work/run'
mount -o remount,bind,ro /
mount -t tmpfs tmpfs /tmp
mount -t tmpfs tmpfs /home
mount -t tmpfs tmpfs /root
if touch /usr/.linetrack-rw-probe 2>/dev/null; then echo 'emulation broken: / is writable'; exit 1; fi
cd '$work/state'
setpriv --reuid=$user --regid=nogroup --clear-groups --no-new-privs \
    env -i PATH=/usr/bin:/bin LINETRACK_IPC_ROOT='$work/run/iceoryx2' sh -eu -c '
        touch /dev/shm/.linetrack-probe-\$\$ && rm /dev/shm/.linetrack-probe-\$\$
        $root/usr/bin/linetrack-synth --frames 8 --quiet --output sequence
        # The installed config, every frame processed however late (a loaded machine).
        cp $root/etc/linetrack/pipeline.toml pipeline.toml
        printf \"[budget]\\ndrop_late = false\\n\" >> pipeline.toml
        $root/usr/bin/linetrack run --quiet --pacing fastest --dataset sequence \
            --config pipeline.toml --run-dir runs/hardened
        grep -q \"\\\"completed\\\"\" runs/hardened/summary.json
    '
"
echo "emulated sandbox: the installed pipeline ran through /dev/shm as $user"
