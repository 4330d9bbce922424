// dynsplines viewer: plays scene.glb (runner/export/gltf.py) with the contact states of data.json.
import * as THREE from 'three';
import { GLTFLoader } from './GLTFLoader.js';
import { OrbitControls } from './OrbitControls.js';

const $ = (id) => document.getElementById(id);
const TINT = { plain: 0xf0a040, reference: 0x60d080 };
const SITE_COLOUR = [0x606060, 0x20e020, 0xff2020]; // clear, contact, penetrating

const data = await (await fetch('data.json')).json();
const gltf = await new GLTFLoader().loadAsync('scene.glb');

const renderer = new THREE.WebGLRenderer({ antialias: true, preserveDrawingBuffer: true });
renderer.setPixelRatio(window.devicePixelRatio);
$('view').appendChild(renderer.domElement);
const scene = new THREE.Scene();
scene.background = new THREE.Color(0x8fb0d8);
scene.add(new THREE.HemisphereLight(0xffffff, 0x445566, 2.0));
const sun = new THREE.DirectionalLight(0xffffff, 1.5);
sun.position.set(-2, 6, 1);
scene.add(sun);
scene.add(gltf.scene);
const grid = new THREE.GridHelper(40, 40, 0x404850, 0x56606a);
grid.position.y = 0.001;
scene.add(grid);

const camera = new THREE.PerspectiveCamera(40, 1, 0.01, 200);
const controls = new OrbitControls(camera, renderer.domElement);

const world = gltf.scene.getObjectByName('world');
const tracks = {};
for (const tr of data.tracks) {
  const root = gltf.scene.getObjectByName(`${tr.name}_pelvis`);
  const clip = gltf.animations.find((a) => a.name === tr.name);
  const mixer = new THREE.AnimationMixer(root);
  const action = mixer.clipAction(clip);
  action.play();
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
  copy.traverse((o) => { if (o.isMesh) { o.material = ghostMat; if (o.name.includes('_site_')) o.visible = false; } });
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
// URL options: ?show=optimized,plain,reference,ghosts,contacts (what is on) & t=SECONDS (start time)
const params = new URLSearchParams(window.location.search);
if (params.has('show')) {
  const on = params.get('show').split(',');
  for (const k of ['optimized', 'plain', 'reference', 'ghosts', 'contacts'])
    if (!$(`show-${k}`).disabled) $(`show-${k}`).checked = on.includes(k);
}
if (params.has('t')) time = Math.min(Math.max(parseFloat(params.get('t')) || t0, t0), t1);
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
