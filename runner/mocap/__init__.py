"""Motion-capture import: BVH parsing and checks, retargeting onto the figure, contacts, keyframes."""
