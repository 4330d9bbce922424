"""The capture's algorithms (docs/architecture.md, `capture/`): a BVH clip read once (`clip.Capture`), its
skeleton recognised, retargeted onto the figure, cleaned up (glitches, hyperextension, root height,
footplant), its scene fitted, its contacts, stance and keys found, and a path written back onto its
skeleton. The commands that use them (`mocap`, `clean`, `keyframes-from-bvh`, `export`) are in
runner/commands; no module here is named like a solver module."""
