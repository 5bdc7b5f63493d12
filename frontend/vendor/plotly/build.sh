#!/bin/sh
# Rebuilds frontend/vendor/plotly/plotly.min.js from the npm registry (run by hand when
# upgrading Plotly; the dashboard itself never needs npm or the internet).
# Needs node >= 20 and npm. The versions are pinned in package.json and package-lock.json.
set -eu
here=$(cd "$(dirname "$0")" && pwd)
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
cp "$here/package.json" "$here/package-lock.json" "$here/entry.js" "$work/"
cd "$work"
npm ci --no-audit --no-fund
version=$(node -p 'require("plotly.js/package.json").version')
# The options of plotly.js's own dist build (its esbuild-config.js): iife, global Plotly,
# global=window, no AMD; the maplibre CSS is only for map traces, which are not included.
./node_modules/.bin/esbuild entry.js --bundle --minify --format=iife --global-name=Plotly \
  --define:global=window --define:define.amd=false --define:process.env.NODE_DEBUG=false \
  --loader:.css=empty --target=es2016 --legal-comments=eof \
  --banner:js="/*! plotly.js v$version, partial bundle for heliotwin (core with scatter, bar, scatterpolar), MIT license; built by frontend/vendor/plotly/build.sh */" \
  --outfile="$here/plotly.min.js"
cp node_modules/plotly.js/LICENSE "$here/LICENSE"
ls -l "$here/plotly.min.js"
