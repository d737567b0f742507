#!/usr/bin/env bash
# The documentation site's browser check drives Debian's chromium (/usr/bin/chromium) through
# Playwright. Install the package when it is missing and this user may; otherwise say what is
# needed and go on (the check then skips with that message).
set -u
if [ -x /usr/bin/chromium ]; then
  exit 0
fi
if command -v apt-get >/dev/null 2>&1 && [ "$(id -u)" = "0" ]; then
  echo "installing chromium (for the documentation site's browser check)"
  apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq \
    --no-install-recommends chromium fonts-dejavu-core >/dev/null
else
  echo "warning: /usr/bin/chromium missing; install Debian's chromium package (the" \
    "documentation site's browser check needs it)" >&2
fi
exit 0
