#!/usr/bin/env bash
# Rebuild the vendored three.js bundle from the versions pinned in package.json / package-lock.json:
#   cd plugins/zooctl-viewer/js && ./build.sh
# Needs node and npm (not needed to install or use the viewer: the bundle is committed).
set -euo pipefail
cd "$(dirname "$0")"
npm ci --no-audit --no-fund
out=../zooctl_viewer/static/vendor
mkdir -p "$out"
node_modules/.bin/esbuild entry.js --bundle --minify --format=iife --target=es2020 \
  --legal-comments=none --outfile="$out/three.bundle.js"
cp node_modules/three/LICENSE "$out/three.LICENSE"
version=$(node -p 'require("./node_modules/three/package.json").version')
printf 'three.js %s (npm "three"), MIT licence: three.LICENSE.\nthree.bundle.js = three + examples/jsm GLTFLoader and OrbitControls, built by plugins/zooctl-viewer/js/build.sh.\n' \
  "$version" > "$out/VERSION"
