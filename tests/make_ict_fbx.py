# Writes an FBX rig of the ICT face with Blender, as an artist's DCC tool would: the
# neutral OBJ imported, each expression OBJ added as a shape key named by its file, then
# Blender's own FBX exporter. test_fbx_rig runs it headless at test time:
#   blender -b --factory-startup --python tests/make_ict_fbx.py -- ICT_DIR OUT.fbx
import os
import sys

import bpy

ict_dir, out_path = sys.argv[sys.argv.index("--") + 1:][:2]

bpy.ops.wm.read_factory_settings(use_empty=True)
# The ICT face is in centimetres: one Blender unit is one centimetre, as an artist working
# on it sets the scene, so the FBX says cm and holds the OBJ numbers.
bpy.context.scene.unit_settings.scale_length = 0.01


def import_obj(path):
    # Blender 3.x's OBJ importer keeps the file's vertex order; Y up, -Z forward is the
    # inverse of what the FBX exporter applies below, so the FBX holds the OBJ's coordinates.
    bpy.ops.wm.obj_import(filepath=path, forward_axis="NEGATIVE_Z", up_axis="Y")
    return bpy.context.selected_objects[0]


face = import_obj(os.path.join(ict_dir, "generic_neutral_mesh.obj"))
face.name = "ICTFace"
face.shape_key_add(name="Basis", from_mix=False)
count = len(face.data.vertices)
coords = [0.0] * (3 * count)
for name in sorted(os.listdir(ict_dir)):
    if not name.endswith(".obj") or name == "generic_neutral_mesh.obj":
        continue
    shape = import_obj(os.path.join(ict_dir, name))
    if len(shape.data.vertices) != count:
        sys.exit(f"{name}: {len(shape.data.vertices)} vertices, the neutral has {count}")
    shape.data.vertices.foreach_get("co", coords)
    key = face.shape_key_add(name=os.path.splitext(name)[0], from_mix=False)
    key.data.foreach_set("co", coords)
    bpy.data.objects.remove(shape, do_unlink=True)

bpy.ops.object.select_all(action="DESELECT")
face.select_set(True)
bpy.context.view_layer.objects.active = face
bpy.ops.export_scene.fbx(filepath=out_path, use_selection=True, object_types={"MESH"},
                         axis_forward="-Z", axis_up="Y", bake_anim=False, add_leaf_bones=False)
print(f"wrote {out_path}: {count} vertices, {len(face.data.shape_keys.key_blocks) - 1} shape keys")
