"""Remakes docs/img/blender_panel.png: the add-on's sidebar panel as a running Blender draws it.

`bpy` as a module has no user interface, so the picture comes from Blender itself under a virtual X
display (Debian's Blender 3.4, Mesa's software OpenGL; not part of the tests or CI). From the repository:

    apt-get install -y blender xvfb xdotool imagemagick
    LIBGL_ALWAYS_SOFTWARE=1 xvfb-run -s "-screen 0 1600x1000x24" \
        blender --factory-startup -p 0 0 1600 1000 --python docs/img/blender_panel.py

It registers the add-on's package (runner/blender/addon) without installing it, imports a shipped CMU clip
with Blender's BVH importer, opens the sidebar, and, as a user would, clicks the *dynsplines* tab and
drags the sidebar wider with xdotool (Blender 3.4 has no `Region.active_panel_category`); then it takes
the 3D viewport with `screen.screenshot_area` and crops it to the figure and the sidebar (ImageMagick).
"""
import builtins
import os
import subprocess
import sys

import bpy

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
OUT = os.path.join(ROOT, "docs", "img", "blender_panel.png")
SHOT = "/tmp/dynsplines-blender-panel.png"
#: [px] the dynsplines tab's centre below the top of the 3D viewport (the 4th tab after Item, Tool,
#: View, at UI scale 1) and left of its right edge
TAB = (230, 14)
#: [px] the panels' left edge (the sidebar's resize handle) left of the viewport's right edge
EDGE = 221
#: [px] how much wider the sidebar is dragged: every option's label whole
WIDER = 240
#: [px] the crop of the viewport: width, height, top (below the viewport's header)
CROP = (911, 680, 56)

sys.path.insert(0, os.path.join(ROOT, "runner", "blender"))
import addon  # noqa: E402

addon.register()

from io_anim_bvh import import_bvh  # noqa: E402

# Blender 3.4's BVH importer opens files in mode "rU", which Debian's Python 3.11 no longer accepts
import_bvh.open = lambda path, mode="r", *a, **k: builtins.open(path, mode.replace("U", ""), *a, **k)  # noqa: SIM115

bpy.context.preferences.view.show_splash = False
for obj in list(bpy.data.objects):
    if obj.type == "MESH":
        bpy.data.objects.remove(obj)
# [m] CMU's unit: 1/0.45 in
bpy.ops.import_anim.bvh(filepath=os.path.join(ROOT, "models", "cmu", "127_33.bvh"), global_scale=0.056444,
                        update_scene_fps=True, update_scene_duration=True)
bpy.context.view_layer.objects.active.show_in_front = True
bpy.context.scene.frame_set(60)


def _viewport():
    win = bpy.context.window_manager.windows[0]
    area = max((a for a in win.screen.areas if a.type == "VIEW_3D"), key=lambda a: a.width * a.height)
    return win, area, {r.type: r for r in area.regions}


def _xdotool(*steps, at=0.0):
    """Run the xdotool steps one per 0.7 s from `at` s on (Blender handles each event before the next)."""
    for i, step in enumerate(steps):
        bpy.app.timers.register(lambda step=step: subprocess.run(["xdotool", *step], check=True) and None,
                                first_interval=at + 0.7 * i)


def setup():
    win, area, regions = _viewport()
    area.spaces.active.show_region_ui = True
    with bpy.context.temp_override(window=win, area=area, region=regions["WINDOW"]):
        bpy.ops.view3d.view_selected()
    bpy.app.timers.register(act, first_interval=1.5)  # once the sidebar has opened


def act():
    win, area, regions = _viewport()
    ui = regions["UI"]
    top = win.height - (area.y + area.height)  # the window fills the X screen from its top left corner
    tab = (str(ui.x + ui.width - TAB[1]), str(top + TAB[0]))
    edge, y = ui.x + ui.width - EDGE, str(top + 200)  # 200 px down: beside the panel, not below it
    _xdotool(["mousemove", *tab], ["click", "1"], ["mousemove", str(edge), y], ["mousedown", "1"],
             ["mousemove", str(edge - WIDER // 2), y], ["mousemove", str(edge - WIDER), y], ["mouseup", "1"],
             ["mousemove", str(win.width - 100), str(win.height - 400)])
    bpy.app.timers.register(shoot, first_interval=6.5)


def shoot():
    win, area, _ = _viewport()
    with bpy.context.temp_override(window=win, area=area):
        bpy.ops.screen.screenshot_area(filepath=SHOT)
    w, h, top = CROP
    subprocess.run(["convert", SHOT, "-crop", f"{w}x{h}+{area.width - w}+{top}", "+repage", "+dither",
                    "-colors", "96", "-strip", f"PNG8:{OUT}"], check=True)  # 96 colours: about 40 kB, text as sharp
    print(f"wrote {OUT}", flush=True)
    bpy.ops.wm.quit_blender()


bpy.app.timers.register(setup, first_interval=1.0)
