// dynsplines viewer: plays scene.glb (runner/export/gltf.py) with the contact states of data.json.
import * as THREE from 'three';
import { GLTFLoader } from './GLTFLoader.js';
import { OrbitControls } from './OrbitControls.js';
import { parseQuery } from './query.js';

const $ = (id) => document.getElementById(id);
const TINT = { plain: 0xf0a040, reference: 0x60d080 };
const SITE_COLOUR = [0x606060, 0x20e020, 0xff2020]; // clear, contact, penetrating

const data = await (await fetch('data.json')).json();
const gltf = await new GLTFLoader().loadAsync('scene.glb');

const renderer = new THREE.WebGLRenderer({ antialias: true, preserveDrawingBuffer: true });
renderer.setPixelRatio(window.devicePixelRatio);
renderer.shadowMap.enabled = true;
renderer.shadowMap.type = THREE.PCFSoftShadowMap;
$('view').appendChild(renderer.domElement);
const scene = new THREE.Scene();
scene.background = new THREE.Color(0x8fb0d8);
scene.add(new THREE.HemisphereLight(0xffffff, 0x445566, 1.3));
// the sun stands almost overhead and follows the figure (frameCamera), so its shadow map stays tight
// around it: the shadow under the feet shows how high they are
const SUN_OFFSET = new THREE.Vector3(-1.0, 6.0, 0.6);
const sun = new THREE.DirectionalLight(0xffffff, 2.2);
sun.position.copy(SUN_OFFSET);
sun.castShadow = true;
sun.shadow.mapSize.set(2048, 2048);
Object.assign(sun.shadow.camera, { left: -3, right: 3, top: 3, bottom: -3, near: 0.5, far: 20 });
sun.shadow.bias = -0.0005;
sun.shadow.normalBias = 0.02;
scene.add(sun, sun.target);
scene.add(gltf.scene);

const world = gltf.scene.getObjectByName('world');
// the scene's static geoms (floor, boxes) take shadows; the figures cast them (below)
for (const node of world.children) {
  if (!node.name.startsWith('geom_')) continue;
  node.traverse((o) => {
    if (!o.isMesh) return;
    o.receiveShadow = true;
    o.castShadow = true;
  });
}
// a grid on the floor to judge distances and heights: 1 m lines over 0.25 m ones, a texture drawn
// here (no download) on a transparent sheet just above the floor (floor_height: data.json; glTF y =
// MuJoCo z), so the floor's shadows show through it. Textured triangles, not GL lines: software WebGL
// drops lines that cross the camera's plane.
function gridTexture() {
  const px = 256, canvas = document.createElement('canvas');
  canvas.width = canvas.height = px;
  const g = canvas.getContext('2d');
  g.clearRect(0, 0, px, px);
  g.fillStyle = 'rgba(235, 240, 250, 0.45)';
  for (let k = 1; k < 4; k++) { g.fillRect(k * px / 4 - 1, 0, 2, px); g.fillRect(0, k * px / 4 - 1, px, 2); }
  g.fillStyle = 'rgba(20, 28, 40, 0.85)';
  g.fillRect(0, 0, 4, px); g.fillRect(0, 0, px, 4);
  const tex = new THREE.CanvasTexture(canvas);
  tex.wrapS = tex.wrapT = THREE.RepeatWrapping;
  tex.anisotropy = renderer.capabilities.getMaxAnisotropy();
  tex.colorSpace = THREE.SRGBColorSpace;
  return tex;
}
const GRID_SIZE = 60; // [m], 1 m cells
const gridTex = gridTexture();
gridTex.repeat.set(GRID_SIZE, GRID_SIZE);
const grid = new THREE.Mesh(new THREE.PlaneGeometry(GRID_SIZE, GRID_SIZE),
                            new THREE.MeshBasicMaterial({ map: gridTex, transparent: true, depthWrite: false }));
grid.name = 'grid';
grid.rotation.x = -Math.PI / 2;
grid.position.y = (data.floor_height ?? 0) + 0.002;
grid.renderOrder = -1;
scene.add(grid);

const camera = new THREE.PerspectiveCamera(40, 1, 0.01, 200);
const controls = new OrbitControls(camera, renderer.domElement);

const tracks = {};
for (const tr of data.tracks) {
  const root = gltf.scene.getObjectByName(`${tr.name}_pelvis`);
  const clip = gltf.animations.find((a) => a.name === tr.name);
  const mixer = new THREE.AnimationMixer(root);
  const action = mixer.clipAction(clip);
  action.play();
  root.traverse((o) => { if (o.isMesh && !o.name.includes('_site_')) o.castShadow = true; });
  const sites = {};
  for (const s of data.sites) {
    const node = gltf.scene.getObjectByName(`${tr.name}_site_${s}`);
    if (node) {
      node.material = node.material.clone();
      node.renderOrder = 2;
      node.material.depthTest = false; // the sites show through the feet
      sites[s] = node;
    }
  }
  if (TINT[tr.name] !== undefined) {
    const mat = new THREE.MeshStandardMaterial({ color: TINT[tr.name], transparent: true, opacity: 0.55,
                                                 roughness: 0.8 });
    root.traverse((o) => { if (o.isMesh && !o.name.includes('_site_')) o.material = mat; });
  }
  tracks[tr.name] = { tr, root, mixer, action, sites };
}
for (const name of ['plain', 'reference']) {
  if (!tracks[name]) { $(`show-${name}`).disabled = true; $(`show-${name}`).parentElement.style.opacity = 0.4; }
}

// keyframe ghosts: copies of the optimized figure posed at the keyframe times
const ghosts = new THREE.Group();
world.add(ghosts);
const opt = tracks.optimized;
const ghostMat = new THREE.MeshStandardMaterial({ color: 0xffffff, transparent: true, opacity: 0.22,
                                                  depthWrite: false });
for (const kt of data.keyframe_times) {
  const copy = opt.root.clone(true);
  copy.traverse((o) => {
    if (o.isMesh) { o.material = ghostMat; o.castShadow = false; if (o.name.includes('_site_')) o.visible = false; }
  });
  const m = new THREE.AnimationMixer(copy);
  m.clipAction(opt.action.getClip()).play();
  m.setTime(Math.max(0, kt - opt.tr.start));
  ghosts.add(copy);
}

const t0 = Math.min(...data.tracks.map((t) => t.start));
const t1 = Math.max(...data.tracks.map((t) => t.start + t.duration));
let time = t0, playing = false, last = performance.now();
$('time').min = t0; $('time').max = t1;

function pose(t) {
  for (const { tr, mixer, action, sites, root } of Object.values(tracks)) {
    const local = Math.min(Math.max(t - tr.start, 0), tr.duration);
    action.time = local;
    mixer.update(0);
    const k = Math.min(tr.samples - 1, Math.round(local * tr.fps));
    for (const [s, node] of Object.entries(sites)) {
      const state = tr.sites[s][k];
      node.material.color.setHex(SITE_COLOUR[state]);
      node.visible = $('show-contacts').checked && root.visible;
      node.scale.setScalar(state ? 1.3 : 0.8);
    }
  }
  $('clock').textContent = `${t.toFixed(3)} s`;
  $('time').value = t;
}

function visibility() {
  for (const name of Object.keys(tracks)) tracks[name].root.visible = $(`show-${name}`).checked;
  ghosts.visible = $('show-ghosts').checked;
  pose(time);
}

const pelvis = new THREE.Vector3();
function frameCamera(first) {
  opt.root.getWorldPosition(pelvis);
  sun.target.position.copy(pelvis);
  sun.position.copy(pelvis).add(SUN_OFFSET);
  if (first) {
    camera.position.set(pelvis.x - 4.6, 1.4, pelvis.z + 0.3);
    controls.target.copy(pelvis);
  } else if ($('follow').checked) {
    const d = pelvis.clone().sub(controls.target);
    d.y = 0;
    camera.position.add(d);
    controls.target.add(d);
  }
  controls.update();
}

function resize() {
  const w = window.innerWidth, h = window.innerHeight;
  renderer.setSize(w, h);
  camera.aspect = w / h;
  camera.updateProjectionMatrix();
}
window.addEventListener('resize', resize);
resize();

$('play').onclick = () => { playing = !playing; $('play').textContent = playing ? 'pause' : 'play';
                            if (playing && time >= t1) time = t0; };
$('time').oninput = () => { time = parseFloat($('time').value); pose(time); };
for (const id of ['show-optimized', 'show-plain', 'show-reference', 'show-ghosts', 'show-contacts'])
  $(id).onchange = visibility;

const pen = Object.entries(data.max_penetration_mm).map(([k, v]) => `${k} ${v.toFixed(1)} mm`).join(', ');
$('info').textContent = `${data.source} - ${data.tracks.length} motions, ${data.keyframe_times.length} keyframes; ` +
                        `deepest contact-site penetration: ${pen}`;
// address options (query.js): ?show= chooses the motions, ?hide= unticks keyframes or contacts, ?t= the time
const query = parseQuery(window.location.search, t0, t1);
if (query.motions) {
  for (const [k, on] of Object.entries(query.motions)) if (!$(`show-${k}`).disabled) $(`show-${k}`).checked = on;
}
for (const [k, on] of Object.entries(query.overlays)) $(`show-${k === 'keyframes' ? 'ghosts' : k}`).checked = on;
if (query.unknown.length) console.warn(`dynsplines view: unknown address options ${query.unknown.join(', ')}`);
if (query.time !== null) time = query.time;
visibility();
frameCamera(true);
window.dynsplinesReady = true;

renderer.setAnimationLoop(() => {
  const now = performance.now();
  if (playing) {
    time += (now - last) / 1000 * parseFloat($('speed').value);
    if (time >= t1) { time = t1; playing = false; $('play').textContent = 'play'; }
    pose(time);
  }
  last = now;
  frameCamera(false);
  renderer.render(scene, camera);
});
