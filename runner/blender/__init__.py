"""The Blender add-on: its code (`runner/blender/addon/`, Blender's side: it imports only `bpy` and the
standard library, and calls the `dynsplines` command in a subprocess) and `write_addon_zip`, which packs
it as an installable extension (`dynsplines blender-addon --out FILE.zip`)."""
