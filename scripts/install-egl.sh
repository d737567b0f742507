#!/usr/bin/env bash
# Headless rendering needs Mesa's software renderers: EGL for MuJoCo, Vulkan (lavapipe) for the
# rerun viewer run headless (crllk.screenshots and its test; without a Vulkan driver the viewer
# falls back to OpenGL and panics). Install the Debian packages whose libraries are missing when
# this user may; otherwise say what is needed and go on.
set -u
# library probed with ldconfig -> the Debian package that ships it
declare -A provider=(
  [libEGL.so.1]=libegl1
  [libEGL_mesa.so.0]=libegl-mesa0
  [libGL.so.1]=libgl1
  [libvulkan.so.1]=libvulkan1
  [libvulkan_lvp.so]=mesa-vulkan-drivers
  [libudev.so.1]=libudev1
)
packages=()
# Mesa's DRI drivers (software GL behind EGL) are not in the linker cache: ask dpkg, if any
if command -v dpkg >/dev/null 2>&1 && ! dpkg -s libgl1-mesa-dri >/dev/null 2>&1; then
  packages+=(libgl1-mesa-dri)
fi
cache=$(ldconfig -p 2>/dev/null)
for library in "${!provider[@]}"; do
  grep -q "${library} " <<<"${cache}" || packages+=("${provider[${library}]}")
done
if [ "${#packages[@]}" -eq 0 ]; then
  exit 0
fi
if command -v apt-get >/dev/null 2>&1 && [ "$(id -u)" = "0" ]; then
  echo "installing rendering libraries: ${packages[*]}"
  apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq \
    --no-install-recommends "${packages[@]}" >/dev/null
else
  echo "warning: rendering libraries missing; install ${packages[*]} (MuJoCo rendering or the" \
    "headless rerun viewer will fail without them)" >&2
fi
exit 0
