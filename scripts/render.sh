#!/usr/bin/env bash
# Renders a .glb to a PNG with three.js in headless Chromium (both from
# Debian/npm; installed on first use). The overcut/undercut volume nodes
# are hidden so the coloured machined surface shows; contact markers stay.
#   bash scripts/render.sh MODEL.glb OUT.png [WIDTH HEIGHT] [AZIMUTH_DEG ELEVATION_DEG]
set -euo pipefail
cd "$(dirname "$0")/.."
glb=$(realpath "$1"); png=$(realpath -m "$2")
w=${3:-1200}; h=${4:-800}; az=${5:-35}; el=${6:-40}
if ! command -v chromium >/dev/null; then
  DEBIAN_FRONTEND=noninteractive apt-get install -y -qq chromium >/dev/null
fi
if [ ! -f build/npm/node_modules/three/build/three.module.js ]; then
  mkdir -p build/npm
  npm install --silent --no-audit --no-fund --prefix build/npm three@0.160.0 >/dev/null
fi
site=$(mktemp -d)
server=""
trap '[ -n "$server" ] && kill "$server" 2>/dev/null; rm -rf "$site"' EXIT
ln -s "$(realpath build/npm/node_modules)" "$site/node_modules"
cp "$glb" "$site/model.glb"
cat > "$site/index.html" <<HTML
<!doctype html><html><body style="margin:0;background:#fff">
<script type="importmap">{"imports":{"three":"/node_modules/three/build/three.module.js","three/addons/":"/node_modules/three/examples/jsm/"}}</script>
<script type="module">
import * as THREE from 'three';
import {GLTFLoader} from 'three/addons/loaders/GLTFLoader.js';
const W = $w, H = $h, az = $az * Math.PI / 180, el = $el * Math.PI / 180;
const renderer = new THREE.WebGLRenderer({antialias: true, preserveDrawingBuffer: true});
renderer.setSize(W, H);
document.body.appendChild(renderer.domElement);
const scene = new THREE.Scene();
scene.background = new THREE.Color(0xffffff);
scene.add(new THREE.HemisphereLight(0xffffff, 0x555555, 1.6));
const sun = new THREE.DirectionalLight(0xffffff, 2.2);
sun.position.set(0.4, 1.0, 0.6);
scene.add(sun);
new GLTFLoader().load('model.glb', (g) => {
  const root = g.scene;
  root.traverse((o) => { if (o.name === 'overcut' || o.name === 'undercut') o.visible = false; });
  scene.add(root);
  const box = new THREE.Box3().setFromObject(root);
  const c = box.getCenter(new THREE.Vector3());
  const s = box.getSize(new THREE.Vector3()).length();
  const cam = new THREE.PerspectiveCamera(30, W / H, s / 100, s * 10);
  cam.position.copy(c).add(new THREE.Vector3(Math.cos(el) * Math.sin(az), Math.sin(el), Math.cos(el) * Math.cos(az)).multiplyScalar(1.45 * s));
  cam.lookAt(c);
  renderer.render(scene, cam);
  document.title = 'rendered';
});
</script></body></html>
HTML
port=$((20000 + RANDOM % 20000))
(cd "$site" && exec python3 -m http.server "$port" --bind 127.0.0.1 >/dev/null 2>&1) &
server=$!
for _ in $(seq 50); do curl -s -o /dev/null "http://127.0.0.1:$port/index.html" && break; sleep 0.1; done
chromium --headless=new --no-sandbox --disable-gpu-sandbox --use-angle=swiftshader --enable-unsafe-swiftshader \
  --hide-scrollbars --window-size="$w,$h" --virtual-time-budget=20000 --screenshot="$png" \
  "http://127.0.0.1:$port/index.html" >/dev/null 2>&1
[ -s "$png" ] || { echo "render: no picture written" >&2; exit 1; }
echo "wrote $png"
