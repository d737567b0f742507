#!/usr/bin/env bash
# Headless MuJoCo rendering needs EGL with Mesa's software renderer. Install the Debian packages
# when they are missing and this user may; otherwise say what is needed and go on.
set -u
packages=(libegl1 libegl-mesa0 libgl1-mesa-dri libgl1)
if ldconfig -p 2>/dev/null | grep -q 'libEGL_mesa.so.0' && ldconfig -p | grep -q 'libEGL.so.1'; then
  exit 0
fi
if command -v apt-get >/dev/null 2>&1 && [ "$(id -u)" = "0" ]; then
  echo "installing EGL libraries: ${packages[*]}"
  apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq "${packages[@]}" >/dev/null
else
  echo "warning: EGL libraries missing; install ${packages[*]} (rendering will fail without them)" >&2
fi
exit 0
