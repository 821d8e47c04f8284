#!/usr/bin/env bash
# Builds the installable Blender extension zip of the isobar fluid-surface add-on:
#
#   bash blender-addon/build.sh            ->  target/blender/isobar_fluid-<version>.zip
#
# 1. `pip wheel ./rust-core/python` builds the isobar wheel (cargo build --release of the
#    core, libisobar.so inside, tag py3-none-linux_x86_64);
# 2. the add-on's files and the wheel (under wheels/) are staged in target/blender/stage,
#    the manifest's `wheels` entry set to the wheel just built;
# 3. the stage is zipped (manifest at the root, fixed timestamps).
#
# Environment: PYTHON (the interpreter running pip, default python3), ISOBAR_BLENDER_OUT
# (output folder, default <repo>/target/blender). Nothing is written into blender-addon/.
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
root="$(cd "$here/.." && pwd)"
python="${PYTHON:-python3}"
out="${ISOBAR_BLENDER_OUT:-$root/target/blender}"
stage="$out/stage/isobar_fluid"

log() { printf '== %s\n' "$*" >&2; }

rm -rf "$stage"
mkdir -p "$stage/wheels"

log "pip wheel ./rust-core/python"
"$python" -m pip wheel --quiet --no-deps --no-build-isolation -w "$stage/wheels" "$root/rust-core/python"

log "stage $stage"
# The add-on itself: its Python modules, manifest and README (no build outputs).
for f in "$here"/*.py "$here/blender_manifest.toml" "$here/README.md"; do
    [ -f "$f" ] && cp "$f" "$stage/"
done

"$python" - "$stage" "$out" <<'PY'
"""Sets the manifest's wheels to the staged wheel(s), checks it, zips the stage."""
import os
import re
import sys
import tomllib
import zipfile

stage, out = sys.argv[1], sys.argv[2]
manifest_path = os.path.join(stage, "blender_manifest.toml")
wheels = sorted(f for f in os.listdir(os.path.join(stage, "wheels")) if f.endswith(".whl"))
if len(wheels) != 1:
    sys.exit(f"build.sh: expected one isobar wheel, found {wheels}")
text = open(manifest_path, encoding="utf-8").read()
listing = "wheels = [" + ", ".join(f'"./wheels/{w}"' for w in wheels) + "]"
text, count = re.subn(r"^wheels\s*=\s*\[[^\]]*\]", listing, text, flags=re.M)
if count != 1:
    sys.exit("build.sh: the manifest has no single `wheels = [...]` line")
open(manifest_path, "w", encoding="utf-8").write(text)

manifest = tomllib.loads(text)
required = ("schema_version", "id", "version", "name", "tagline", "maintainer", "type", "blender_version_min", "license")
missing = [k for k in required if k not in manifest]
if missing:
    sys.exit(f"build.sh: manifest lacks {missing}")
if not manifest["tagline"] or manifest["tagline"].endswith((".", "!", "?")) or len(manifest["tagline"]) > 64:
    sys.exit("build.sh: tagline must be 1-64 characters, not ending in punctuation")

zip_path = os.path.join(out, f"{manifest['id']}-{manifest['version']}.zip")
tmp = zip_path + ".tmp"
with zipfile.ZipFile(tmp, "w", compression=zipfile.ZIP_DEFLATED) as archive:
    for folder, dirs, files in os.walk(stage):
        dirs[:] = sorted(d for d in dirs if d != "__pycache__")
        for name in sorted(files):
            path = os.path.join(folder, name)
            arcname = os.path.relpath(path, stage).replace(os.sep, "/")
            info = zipfile.ZipInfo(arcname, date_time=(1980, 1, 1, 0, 0, 0))
            info.compress_type = zipfile.ZIP_STORED if name.endswith(".whl") else zipfile.ZIP_DEFLATED
            info.external_attr = 0o644 << 16
            with open(path, "rb") as f:
                archive.writestr(info, f.read())
os.replace(tmp, zip_path)
print(zip_path)
PY
