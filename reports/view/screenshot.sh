#!/usr/bin/env bash
# The README's picture of `fogray view`: the page of a model, screenshotted by headless
# Chromium after a drag (the page's ?drag=DX,DY hook drags through the mouse handlers). The
# budget is of Chromium's virtual time, which runs ahead of the clock while a frame is awaited;
# once the page is still, the rest of it passes at once.
#   reports/view/screenshot.sh FOGRAY MODEL [OUT.png]
# e.g. reports/view/screenshot.sh target/release/fogray lego.safetensors reports/view/screenshot.png
set -euo pipefail
fogray=$1 model=$2 out=${3:-reports/view/screenshot.png}
profile=$(mktemp -d)
log=$(mktemp)
"$fogray" view --model "$model" >"$log" &
server=$!
trap 'kill -INT $server 2>/dev/null || true; rm -rf "$profile" "$log"' EXIT
until grep -q '^fogray view: http' "$log"; do
  kill -0 "$server" || exit 1
  sleep 0.2
done
url=$(sed -n 's/^fogray view: //p' "$log")
chromium --headless --disable-gpu --no-sandbox --hide-scrollbars --force-device-scale-factor=1 \
  --window-size=860,420 --user-data-dir="$profile" --virtual-time-budget=3600000 \
  --screenshot="$out" "${url}?w=400&h=400&drag=60,-10"
