#!/usr/bin/env bash
# The README's two commands, verbatim, as root in a fresh Debian container.
#
#   bash tests/boot/readme-in-container.sh SUITE [WORK]     (SUITE: bookworm or trixie)
#
# debootstrap's minbase of SUITE (plus sudo, which the README's lines call), cached in
# WORK/SUITE-base; a fresh copy of it per run, a clean clone of this repository's HEAD
# in /root/kasparctl, and systemd-nspawn running the README's demo and test commands
# there with this machine's network (apt and pip reach their registries). The test
# command boots its own container inside this one (tests/test_boot.py). The output is
# in WORK/runs/SUITE/out.log; the last lines say each command's exit status.
set -euo pipefail
suite=${1:?usage: readme-in-container.sh bookworm|trixie [WORK]}
work=${2:-/var/tmp/kasparctl-readme}
repo=$(git -C "$(dirname "$0")" rev-parse --show-toplevel)
base=$work/$suite-base
run=$work/runs/$suite
[ "$(id -u)" -eq 0 ] || { echo "needs root (debootstrap, systemd-nspawn)" >&2; exit 1; }
if [ ! -e "$base/.complete" ]; then
  rm -rf --one-file-system "$base"
  debootstrap --variant=minbase --include=sudo "$suite" "$base" http://deb.debian.org/debian
  touch "$base/.complete"
fi
rm -rf --one-file-system "$run"
mkdir -p "$run"
cp -a "$base" "$run/root"
git clone -q "$repo" "$run/root/root/kasparctl"
# The README's lines, as it has them: the first two commands of its first sh block.
mapfile -t commands < <(awk '/^```sh$/ {inside = 1; next} /^```$/ {exit} inside && !/^#/ && NF' \
  "$run/root/root/kasparctl/README.md")
script="${commands[0]}; echo \"demo: exit \$?\"; ${commands[1]}; echo \"tests: exit \$?\""
extra=()
# A network whose TLS is re-signed by its own authority: pip's file of it goes in too.
if [ -n "${PIP_CERT:-}" ] && [ -f "$PIP_CERT" ]; then
  extra+=("--bind-ro=$PIP_CERT:/etc/ssl/pip-cert.pem" "--setenv=PIP_CERT=/etc/ssl/pip-cert.pem")
fi
SYSTEMD_NSPAWN_UNIFIED_HIERARCHY=1 systemd-nspawn --register=no --keep-unit --as-pid2 --quiet \
  --machine="readme-$suite" -D "$run/root" --chdir=/root/kasparctl --setenv=HOME=/root \
  --setenv=TERM=dumb --setenv=LANG=C.UTF-8 "${extra[@]}" \
  bash -c "$script" </dev/null >"$run/out.log" 2>&1 || true
tail -n 4 "$run/out.log"
