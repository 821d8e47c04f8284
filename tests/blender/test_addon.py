"""The packaged extension installs, enables and registers like a user's would."""

import os
import subprocess
import sys
import zipfile

import bpy
from conftest import MODULE, ZIP


def test_zip_is_an_extension_with_the_isobar_and_isobar_usd_wheels():
    with zipfile.ZipFile(ZIP) as archive:
        names = archive.namelist()
        manifest = archive.read("blender_manifest.toml").decode()
    assert "__init__.py" in names and "usd_export.py" in names
    wheels = sorted(n for n in names if n.startswith("wheels/") and n.endswith(".whl"))
    assert len(wheels) == 2, wheels
    assert wheels[0].startswith("wheels/isobar-") and wheels[0].endswith("-py3-none-linux_x86_64.whl"), wheels
    assert wheels[1].startswith("wheels/isobar_usd-") and wheels[1].endswith("-py3-none-any.whl"), wheels
    assert "wheels = [" + ", ".join(f'"./{w}"' for w in wheels) + "]" in manifest
    assert 'id = "isobar_fluid"' in manifest and 'platforms = ["linux-x64"]' in manifest


def test_blender_validates_the_zip():
    """Blender's own extension tool (blender_ext.py validate) accepts the archive."""
    tool = os.path.join(bpy.utils.system_resource("SCRIPTS"), "addons_core", "bl_pkg", "cli", "blender_ext.py")
    result = subprocess.run([sys.executable, tool, "validate", str(ZIP)], capture_output=True, text=True, check=False)
    assert result.returncode == 0, result.stdout + result.stderr
    assert "Success" in result.stdout


def test_installed_and_enabled(addon, isobar):
    assert MODULE in bpy.context.preferences.addons
    # The add-on lives in the user extension repository, the isobar package comes from its
    # wheel (Blender's extension site-packages), with the library inside the package.
    user = os.environ["BLENDER_USER_RESOURCES"]
    assert addon.__file__.startswith(user), addon.__file__
    assert isobar.__file__.startswith(user), isobar.__file__
    assert os.path.dirname(isobar.library_path) == os.path.dirname(isobar.__file__)
    assert isobar.core_version() == isobar.__version__
    for op in ("import_sequence", "surface_from_object", "refresh", "bake", "free_bake", "export_usd"):
        assert hasattr(bpy.ops.isobar, op)
    assert bpy.types.ISOBAR_PT_main.bl_category == "isobar"
    assert bpy.types.ISOBAR_PT_main.bl_region_type == "UI"
    names = [h.__name__ for h in bpy.app.handlers.frame_change_post]
    assert names.count("isobar_frame_change_post") == 1


def test_disable_and_enable_again(addon):
    import addon_utils

    addon_utils.disable(MODULE)
    assert not hasattr(bpy.types.Object, "isobar")
    assert "isobar_frame_change_post" not in [h.__name__ for h in bpy.app.handlers.frame_change_post]
    addon_utils.enable(MODULE, default_set=True)
    assert hasattr(bpy.types.Object, "isobar")
    assert [h.__name__ for h in bpy.app.handlers.frame_change_post].count("isobar_frame_change_post") == 1
    assert MODULE in sys.modules


def test_import_menu_entry(addon):
    # The File > Import entry is a draw function appended to the menu.
    draw_funcs = bpy.types.TOPBAR_MT_file_import._dyn_ui_initialize()
    assert any(getattr(f, "__module__", "").startswith(MODULE) for f in draw_funcs)
