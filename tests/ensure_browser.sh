#!/usr/bin/env bash
# `make test` runs this first: the viewer test drives a real headless Chromium.
# Found already (HEXAPOD_BROWSER, chromium-headless-shell, chromium): nothing to do.
# Missing, with apt-get and the right to install (root, or password-less sudo):
# installs Debian's chromium-headless-shell. Otherwise: one line saying what to
# install, and a non-zero exit (the test must run, never skip).
set -u
if [ -n "${HEXAPOD_BROWSER:-}" ]; then
  if [ -x "$HEXAPOD_BROWSER" ]; then exit 0; fi
  echo "make test: HEXAPOD_BROWSER=$HEXAPOD_BROWSER is not an executable file" >&2
  exit 1
fi
for name in chromium-headless-shell chromium chromium-browser google-chrome; do
  if command -v "$name" >/dev/null 2>&1; then exit 0; fi
done
sudo=""
if [ "$(id -u)" != 0 ]; then
  if command -v sudo >/dev/null 2>&1 && sudo -n true 2>/dev/null; then sudo="sudo -n"; else sudo="none"; fi
fi
if command -v apt-get >/dev/null 2>&1 && [ "$sudo" != none ]; then
  echo "make test: no headless browser for the viewer test; installing Debian's chromium-headless-shell (apt-get)"
  export DEBIAN_FRONTEND=noninteractive
  if $sudo apt-get update -qq && $sudo apt-get install -y -qq chromium-headless-shell >/dev/null; then
    exit 0
  fi
  echo "make test: apt-get could not install chromium-headless-shell; trying chromium" >&2
  $sudo apt-get install -y -qq chromium >/dev/null && exit 0
fi
echo "make test: the viewer test needs a headless Chromium: install Debian's 'chromium-headless-shell' (or 'chromium'), or set HEXAPOD_BROWSER=/path/to/chrome" >&2
exit 1
