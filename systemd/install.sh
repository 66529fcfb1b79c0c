#!/usr/bin/env bash
# Installs kasparctl as a systemd service on Debian 12 or Raspberry Pi OS (bookworm).
#
#   bash systemd/install.sh              as root, from a checkout of kasparctl
#   bash systemd/install.sh --dry-run    prints every step, changes nothing
#   bash systemd/install.sh --uninstall  removes the service, /opt/kasparctl, the udev rules
#                                        and the kaspar user; keeps the research records
#                                        (/var/lib/kaspar) and the configuration (/etc/kaspar)
#   bash systemd/install.sh --packages   the Debian packages it needs, one a line
#
# It needs nothing but bash and what Debian itself ships. Running it again brings an
# install up to date; it never overwrites /etc/kaspar/kaspar.toml nor udev rules you
# edited. The checkout is only read: the wheel is built in a temporary copy.
# A robot without network installs from a folder of wheels, through pip's own settings:
#   PIP_NO_INDEX=1 PIP_FIND_LINKS=/path/to/wheels bash systemd/install.sh
set -euo pipefail
# Root's umask may be 077 on a hardened system: the service's user must still be
# able to read the venv, the unit and the rules.
umask 022

HERE=$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)
CHECKOUT=$(dirname "$HERE")
PREFIX=/opt/kasparctl
UNIT=kasparctl.service
UNIT_FILE=/etc/systemd/system/$UNIT
SYSUSERS_FILE=/etc/sysusers.d/kasparctl.conf
MODULES_FILE=/etc/modules-load.d/kasparctl.conf
RULES_DIR=/etc/udev/rules.d
RULES=(99-kaspar-serial.rules 99-kaspar-keyfob.rules 99-kaspar-researcher.rules)
CONFIG_DIR=/etc/kaspar
CONFIG=$CONFIG_DIR/kaspar.toml
STATE_DIR=/var/lib/kaspar
SERVICE_USER=kaspar
# python3-dev, gcc and libc6-dev build python-evdev (no wheels); espeak-ng speaks;
# alsa-utils' aplay plays; kmod and udev load the adapters' modules and apply the rules.
PACKAGES=(python3 python3-venv python3-dev gcc libc6-dev espeak-ng alsa-utils kmod udev)

usage() {
  sed -n '2,9s/^# \{0,1\}//p' "${BASH_SOURCE[0]}"
}

MODE=install
DRY_RUN=0
for argument in "$@"; do
  case $argument in
    --dry-run) DRY_RUN=1 ;;
    --uninstall) MODE=uninstall ;;
    --packages) MODE=packages ;;
    -h | --help) usage; exit 0 ;;
    *) printf 'install.sh: unknown option %s\n\n' "$argument" >&2; usage >&2; exit 2 ;;
  esac
done

# -- how each step is shown and done ------------------------------------------------

step_number=0
step() {
  step_number=$((step_number + 1))
  printf '\n# %d. %s\n' "$step_number" "$1"
}

# Prints a command as it would be typed (with the quoting it needs), then runs it.
run() {
  local quoted
  printf -v quoted '%q ' "$@"
  printf '%s\n' "${quoted% }"
  ((DRY_RUN)) || "$@"
}

# As run, for a command given as one line of shell (a pipeline).
run_shell() {
  printf '%s\n' "$1"
  ((DRY_RUN)) || bash -o pipefail -c "$1"
}

# As run, but a failure is explained and the install goes on: the step is one that
# cannot work on some machines (no kernel modules in a container, no udev daemon).
# Returns the command's status so that a following step can depend on it.
run_tolerating() {
  local why=$1
  shift
  local quoted
  printf -v quoted '%q ' "$@"
  printf '%s\n' "${quoted% }"
  ((DRY_RUN)) && return 0
  if "$@"; then
    return 0
  fi
  printf 'note: %s\n' "$why"
  return 1
}

note() {
  printf '%s\n' "$*"
}

fail() {
  printf 'install.sh: %s\n' "$*" >&2
  exit 1
}

need_root() {
  ((DRY_RUN)) && return 0
  [ "$(id -u)" -eq 0 ] || fail "run it as root (su -, then bash $0; or sudo bash $0), or with --dry-run to see the steps"
}

systemd_is_running() {
  [ -d /run/systemd/system ]
}

missing_packages() {
  local package
  for package in "${PACKAGES[@]}"; do
    dpkg-query -W -f='${Status}\n' "$package" 2>/dev/null | grep -q '^install ok installed$' ||
      printf '%s\n' "$package"
  done
}

# -- install --------------------------------------------------------------------------

install_packages() {
  local missing
  mapfile -t missing < <(missing_packages)
  step "Debian packages: ${PACKAGES[*]}"
  if ((${#missing[@]} == 0)); then
    note "all installed"
    return
  fi
  export DEBIAN_FRONTEND=noninteractive
  run apt-get update
  run apt-get install -y --no-install-recommends "${missing[@]}"
}

check_python() {
  ((DRY_RUN)) && ! command -v python3 >/dev/null && return 0
  python3 -c 'import sys; sys.exit(sys.version_info < (3, 11))' ||
    fail "kasparctl needs Python 3.11 or newer; this system's python3 is $(python3 -V 2>&1) (Debian 12 or Raspberry Pi OS bookworm have 3.11)"
}

install_venv() {
  step "kasparctl in its own virtual environment, $PREFIX"
  if [ -x "$PREFIX/bin/python" ]; then
    note "$PREFIX exists: kasparctl is brought up to date in it"
  else
    run python3 -m venv "$PREFIX"
  fi

  step "the wheel, built from a temporary copy of the checkout (which stays as it is)"
  local build wheel
  if ((DRY_RUN)); then
    build=${TMPDIR:-/tmp}/kasparctl-build.XXXXXXXXXX
  else
    build=$(mktemp -d "${TMPDIR:-/tmp}/kasparctl-build.XXXXXXXXXX")
    # shellcheck disable=SC2064  # the path is fixed now, on purpose
    trap "rm -rf '$build'" EXIT
  fi
  run mkdir -p "$build/src" "$build/wheel"
  local copy
  printf -v copy "tar -C %q --exclude=./.git --exclude=./.venv --exclude=./build --exclude=./dist --exclude='*.egg-info' --exclude=__pycache__ --exclude='.*_cache' --exclude=.hypothesis -cf - . | tar -C %q -xf -" \
    "$CHECKOUT" "$build/src"
  run_shell "$copy"
  run "$PREFIX/bin/pip" wheel --quiet --no-deps --wheel-dir "$build/wheel" "$build/src"
  if ((DRY_RUN)); then
    wheel="$build/wheel/kasparctl-VERSION-py3-none-any.whl"
  else
    wheel=$(find "$build/wheel" -name 'kasparctl-*.whl' -print -quit)
    [ -n "$wheel" ] || fail "pip built no kasparctl wheel in $build/wheel"
  fi

  step "kasparctl and its dependencies into $PREFIX (the same version is replaced too)"
  run "$PREFIX/bin/pip" install --quiet "$wheel"
  run "$PREFIX/bin/pip" install --quiet --no-deps --force-reinstall "$wheel"
}

install_user() {
  step "the service's user, $SERVICE_USER, in the dialout, input and audio groups"
  run install -D -m 0644 "$HERE/kasparctl-sysusers.conf" "$SYSUSERS_FILE"
  run systemd-sysusers "$SYSUSERS_FILE"
}

install_modules() {
  step "the serial adapters' kernel modules, at every boot and now (DeviceAllow= needs their device groups)"
  run install -D -m 0644 "$HERE/kasparctl-modules.conf" "$MODULES_FILE"
  local modules
  mapfile -t modules < <(sed -e 's/#.*//' -e '/^[[:space:]]*$/d' "$HERE/kasparctl-modules.conf")
  run_tolerating "the modules could not be loaded now (a container, or a kernel without them); the service allows /dev/ttyUSB* and /dev/ttyACM* only once they are loaded, at the next boot" \
    modprobe -a "${modules[@]}" || true
}

install_rules() {
  step "stable device names for the servo buses, the keyfob and the researcher's remote (your edited rules are kept)"
  local rule
  for rule in "${RULES[@]}"; do
    if [ ! -e "$RULES_DIR/$rule" ]; then
      run install -D -m 0644 "$HERE/$rule" "$RULES_DIR/$rule"
    elif cmp -s "$HERE/$rule" "$RULES_DIR/$rule"; then
      note "$RULES_DIR/$rule is up to date"
    else
      note "$RULES_DIR/$rule differs from systemd/$rule: kept yours (diff them to see what changed)"
    fi
  done
  if run_tolerating "udev is not running here (a container?): the rules apply from the next boot" \
    udevadm control --reload; then
    run_tolerating "udevadm trigger failed: the rules apply when the devices are next plugged in" \
      udevadm trigger --action=change --subsystem-match=tty --subsystem-match=input || true
    run_tolerating "udevadm trigger failed: the latency rule applies when the adapter is next plugged in" \
      udevadm trigger --action=add --subsystem-match=usb-serial || true
  fi
}

install_config() {
  step "the configuration, $CONFIG (only if there is none: yours is never overwritten)"
  if [ -e "$CONFIG" ]; then
    note "$CONFIG exists: kept"
    return
  fi
  run install -d -m 0755 "$CONFIG_DIR"
  # Readable by the service, not by everyone: the plan may hold children's first names.
  run install -m 0640 -o root -g "$SERVICE_USER" "$HERE/kaspar.toml" "$CONFIG"
  note "edit it for your robot (start from systemd/kaspar-1c.toml or systemd/kaspar-3.toml for [servos])"
}

install_unit() {
  step "the service, enabled at boot and started now"
  run install -D -m 0644 "$HERE/$UNIT" "$UNIT_FILE"
  if ! systemd_is_running; then
    run systemctl enable "$UNIT"
    note "systemd is not running here (an image being built?): the service starts at the next boot"
    return
  fi
  run systemctl daemon-reload
  # A unit that failed before (an earlier, broken install) may have hit its start
  # limit; start refuses such a unit until the failure is cleared.
  if ((!DRY_RUN)) && systemctl is-failed --quiet "$UNIT"; then
    run systemctl reset-failed "$UNIT"
  fi
  run systemctl enable "$UNIT"
  if ((!DRY_RUN)) && systemctl is-active --quiet "$UNIT"; then
    note "$UNIT was already running: it runs the new version once restarted, between sessions: systemctl restart $UNIT"
    return
  fi
  if ! run systemctl start "$UNIT"; then
    systemctl status --no-pager --lines=20 "$UNIT" || true
    fail "$UNIT did not start; the journal above says why (journalctl -u $UNIT for more)"
  fi
}

do_install() {
  need_root
  [ -f "$CHECKOUT/pyproject.toml" ] || fail "$CHECKOUT is not a checkout of kasparctl (no pyproject.toml)"
  ((DRY_RUN)) && note "# Dry run: each step is printed, nothing is changed."
  install_packages
  check_python
  install_venv
  install_user
  install_modules
  install_rules
  install_config
  install_unit
  cat <<EOF

# Done. Next:
#   edit $CONFIG for the robot, then: systemctl reload $UNIT (between sessions)
#   check the hardware (the service holds the ports, so stop it first):
#     systemctl stop $UNIT && runuser -u $SERVICE_USER -- $PREFIX/bin/kasparctl check; systemctl start $UNIT
#   follow it: journalctl -u $UNIT -f
EOF
}

# -- uninstall --------------------------------------------------------------------------

do_uninstall() {
  need_root
  ((DRY_RUN)) && note "# Dry run: each step is printed, nothing is changed."
  step "the service, stopped and removed"
  if systemd_is_running; then
    run_tolerating "$UNIT was not loaded" systemctl disable --now "$UNIT" || true
  fi
  run rm -f "$UNIT_FILE"
  if systemd_is_running; then
    run systemctl daemon-reload
    run_tolerating "nothing to reset" systemctl reset-failed "$UNIT" 2>/dev/null || true
  fi
  if [ -d "$UNIT_FILE.d" ]; then
    note "kept your drop-ins in $UNIT_FILE.d"
  fi

  step "the virtual environment, $PREFIX"
  run rm -rf "$PREFIX"

  step "the udev rules and the modules-load file (loaded modules stay until the next boot)"
  local rule
  for rule in "${RULES[@]}"; do
    run rm -f "$RULES_DIR/$rule"
  done
  run_tolerating "udev is not running here: nothing to reload" udevadm control --reload || true
  run rm -f "$MODULES_FILE"

  step "the service's user, $SERVICE_USER"
  run rm -f "$SYSUSERS_FILE"
  if getent passwd "$SERVICE_USER" >/dev/null; then
    run userdel "$SERVICE_USER"
  fi
  if getent group "$SERVICE_USER" >/dev/null; then
    run groupdel "$SERVICE_USER"
  fi

  local sessions=0
  if [ -d "$STATE_DIR/sessions" ]; then
    sessions=$(find "$STATE_DIR/sessions" -mindepth 1 -maxdepth 1 -type d | wc -l)
  fi
  cat <<EOF

# Kept: the research records in $STATE_DIR ($sessions sessions) and the configuration in $CONFIG_DIR.
# A new install uses them as they are (systemd gives the records to the new kaspar user).
# To delete them as well, after exporting what you need: rm -r $STATE_DIR $CONFIG_DIR
# The Debian packages stay installed (other software may use them): ${PACKAGES[*]}
EOF
}

case $MODE in
  packages) printf '%s\n' "${PACKAGES[@]}" ;;
  install) do_install ;;
  uninstall) do_uninstall ;;
esac
