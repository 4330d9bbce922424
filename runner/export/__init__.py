"""Results out: a saved path (.npz) sampled at a frame rate and written as BVH (`bvh`) or glTF binary (`gltf`).

`sampling` reads the saved path and samples its optimized, plain or reference motion; the writers take
MuJoCo `qpos` samples and the loaded model (offsets, geoms and the static scene come from the model).
"""
