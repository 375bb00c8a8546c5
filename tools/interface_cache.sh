#!/usr/bin/env bash
# The built interfaces' cache of tools/setup.sh: one install tree of freejoint_msgs per entry.
#
#   interface_cache.sh save ENTRY ROOT      ROOT/install/freejoint_msgs -> ENTRY
#   interface_cache.sh restore ENTRY ROOT   ENTRY -> ROOT/install/freejoint_msgs
#
# An entry (a folder named by its key: the interface sources and the pins) holds the
# install tree with its symlinks resolved (colcon's --symlink-install points into the build
# tree, which is not kept), without bytecode, and in "root" the checkout it was built in.
# A restore rewrites that checkout's path to ROOT in the tree's text files (its environment
# hooks, package.sh, CMake exports; the libraries load by name, not by path). Saving keeps
# the three newest entries beside ENTRY. Exit status 0 when done, 1 when not (nothing left
# half-written in ENTRY or ROOT/install/freejoint_msgs).
set -euo pipefail
PKG=freejoint_msgs
[ $# -eq 3 ] || { echo "usage: $0 save|restore ENTRY ROOT" >&2; exit 2; }
cmd=$1
entry=$2
root=$3
# For sed's s|old|new|: the characters sed reads specially on either side.
escape() { printf '%s' "$1" | sed -e 's/[][\\|&.*^$/]/\\&/g'; }

case $cmd in
save)
  tmp="$entry.tmp.$$"
  trap 'rm -rf "$tmp"' EXIT
  rm -rf "$tmp"
  mkdir -p "$tmp"
  cp -rL "$root/install/$PKG" "$tmp/" || exit 1
  find "$tmp" -name __pycache__ -prune -exec rm -rf {} +
  printf '%s' "$root" >"$tmp/root"
  # Replaced by renames, so that a restore running meanwhile finds a whole entry or none.
  if [ -e "$entry" ]; then
    mv "$entry" "$entry.tmp.old.$$"
    mv "$tmp" "$entry"
    rm -rf "$entry.tmp.old.$$"
  else
    mv "$tmp" "$entry"
  fi
  find "$(dirname "$entry")" -mindepth 1 -maxdepth 1 -type d ! -name '*.tmp.*' \
    -printf '%T@ %p\n' | sort -rn | tail -n +4 | cut -d' ' -f2- \
    | while IFS= read -r old; do rm -rf "$old"; done
  ;;
restore)
  [ -f "$entry/root" ] && [ -d "$entry/$PKG" ] || exit 1
  old=$(cat "$entry/root")
  rm -rf "$root/install/$PKG" "$root/build/$PKG"
  mkdir -p "$root/install"
  touch "$root/install/COLCON_IGNORE"     # as colcon marks it: no package is found in it
  if ! cp -r "$entry/$PKG" "$root/install/"; then
    rm -rf "$root/install/$PKG"
    exit 1
  fi
  if [ "$old" != "$root" ]; then
    from=$(escape "$old")
    to=$(escape "$root")
    grep -rlI -F "$old" "$root/install/$PKG" | while IFS= read -r f; do
      sed -i "s|$from|$to|g" "$f"
    done
  fi
  ;;
*)
  echo "usage: $0 save|restore ENTRY ROOT" >&2
  exit 2
  ;;
esac
