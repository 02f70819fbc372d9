# Writes tests/data/tiny_rig_blender.fbx, the small FBX rig the FBX tests and the fbx fuzz
# target's seeds use without needing Blender: a cube (8 vertices, whose UV seams make
# assimp deliver 24) with two shape keys, exported by Blender's own FBX exporter.
#   blender -b --factory-startup --python tests/make_tiny_fbx.py -- tests/data/tiny_rig_blender.fbx
import sys

import bpy

out_path = sys.argv[sys.argv.index("--") + 1]
bpy.ops.wm.read_factory_settings(use_empty=True)
bpy.context.scene.unit_settings.scale_length = 0.01  # centimetres, as the ICT rig
bpy.ops.mesh.primitive_cube_add(size=10.0, calc_uvs=True)
cube = bpy.context.active_object
cube.name = "TinyFace"
cube.shape_key_add(name="Basis", from_mix=False)
jaw = cube.shape_key_add(name="jawOpen", from_mix=False)
smile = cube.shape_key_add(name="mouthSmile_L", from_mix=False)
for i, point in enumerate(jaw.data):
    if point.co.z < 0:
        point.co.z -= 2.0 + 0.25 * i  # each vertex its own displacement
for i, point in enumerate(smile.data):
    if point.co.x > 0:
        point.co.y += 1.0 + 0.125 * i
bpy.ops.export_scene.fbx(filepath=out_path, use_selection=True, object_types={"MESH"},
                         axis_forward="-Z", axis_up="Y", bake_anim=False, add_leaf_bones=False)
