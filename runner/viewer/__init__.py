"""`dynsplines view PATH.npz`: a local web page that plays a saved path in its scene.

Choice: a self-contained page that plays a .glb with three.js, served by the standard library's
`http.server`, rather than viser. It reuses the glTF export (`runner.export.gltf`: the figure, its
scene, one animation per motion), so the viewer shows the poses `dynsplines export --to FILE.glb` writes
(there as an armature with skinned meshes, here as rigid meshes in the body nodes, which the page copies
for the keyframe ghosts), and it needs no Python dependency at all: three.js r160 is vendored under `static/` (the minified
module build, GLTFLoader, BufferGeometryUtils and OrbitControls: 0.84 MB, MIT licence in
`static/LICENSE.three.txt`), and the page runs offline. viser would add websockets and a server-side
scene graph updated per frame, for a page that only needs to play a precomputed animation.

The server (`server.py`) binds 127.0.0.1 only and serves the static files and two generated resources:
`scene.glb` (every motion of the path as its own figure and animation, with the contact sites as small
spheres) and `data.json` (times, keyframe times, the floor's height, and per motion and sample the state
of each contact site: clear, in contact or penetrating).

The page (`static/viewer.js`) draws a 1 m grid on the floor and the figures' shadows from a sun that
follows the optimized figure, so heights above the floor can be judged. Its address options are parsed
by `static/query.js`: `?show=optimized,plain,reference` (or `none`) chooses the motions shown and
leaves the keyframes and contacts alone, `?hide=keyframes,contacts` unticks those, `?t=SECONDS` sets
the time.
"""
