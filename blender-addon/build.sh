#!/usr/bin/env bash
# Builds the installable Blender extension zip of the isobar fluid-surface add-on:
#
#   bash blender-addon/build.sh            ->  target/blender/isobar_fluid-<version>.zip
#
# 1. `pip wheel ./rust-core/python` builds the isobar wheel (cargo build --release of the
#    core, libisobar.so inside, tag py3-none-linux_x86_64);
# 2. the isobar_usd wheel (the USD writer, pure Python, py3-none-any) is packed from
#    ./usd-exporter by the Python below (no build backend, no index; its usd-core
#    requirement is met by the pxr module Blender ships, extension wheels are installed
#    without dependencies);
# 3. the add-on's files and the wheels (under wheels/) are staged in target/blender/stage,
#    the manifest's `wheels` entry set to the wheels just built;
# 4. the stage is zipped (manifest at the root, fixed timestamps).
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

log "wheel ./usd-exporter (isobar_usd)"
"$python" - "$root/usd-exporter" "$stage/wheels" <<'PY'
"""Packs the pure-Python isobar_usd package into a wheel (PEP 427), deterministically."""
import base64
import hashlib
import os
import re
import sys
import tomllib
import zipfile

src, dest = sys.argv[1], sys.argv[2]
project = tomllib.load(open(os.path.join(src, "pyproject.toml"), "rb"))["project"]
version = re.search(r'__version__\s*=\s*"([^"]+)"', open(os.path.join(src, "isobar_usd", "_version.py")).read()).group(1)
name = "isobar_usd"
dist_info = f"{name}-{version}.dist-info"
files = []
for folder, dirs, names in os.walk(os.path.join(src, name)):
    dirs[:] = sorted(d for d in dirs if d != "__pycache__")
    for n in sorted(names):
        if n.endswith((".py", ".typed")):
            path = os.path.join(folder, n)
            files.append((os.path.relpath(path, src).replace(os.sep, "/"), open(path, "rb").read()))
metadata = [f"Metadata-Version: 2.1", f"Name: {project['name']}", f"Version: {version}",
            f"Summary: {project.get('description', '')}", f"Requires-Python: {project.get('requires-python', '>=3.9')}"]
metadata += [f"Requires-Dist: {d}" for d in project.get("dependencies", [])]
files.append((f"{dist_info}/METADATA", ("\n".join(metadata) + "\n").encode()))
files.append((f"{dist_info}/WHEEL", b"Wheel-Version: 1.0\nGenerator: isobar build.sh\nRoot-Is-Purelib: true\nTag: py3-none-any\n"))
record = []
for arcname, data in files:
    digest = base64.urlsafe_b64encode(hashlib.sha256(data).digest()).rstrip(b"=").decode()
    record.append(f"{arcname},sha256={digest},{len(data)}")
record.append(f"{dist_info}/RECORD,,")
files.append((f"{dist_info}/RECORD", ("\n".join(record) + "\n").encode()))
wheel = os.path.join(dest, f"{name}-{version}-py3-none-any.whl")
with zipfile.ZipFile(wheel, "w", compression=zipfile.ZIP_DEFLATED) as archive:
    for arcname, data in files:
        info = zipfile.ZipInfo(arcname, date_time=(1980, 1, 1, 0, 0, 0))
        info.compress_type = zipfile.ZIP_DEFLATED
        info.external_attr = 0o644 << 16
        archive.writestr(info, data)
PY

"$python" - "$stage" "$out" <<'PY'
"""Sets the manifest's wheels to the staged wheels, checks it, zips the stage."""
import os
import re
import sys
import tomllib
import zipfile

stage, out = sys.argv[1], sys.argv[2]
manifest_path = os.path.join(stage, "blender_manifest.toml")
wheels = sorted(f for f in os.listdir(os.path.join(stage, "wheels")) if f.endswith(".whl"))
core = [w for w in wheels if w.startswith("isobar-")]
writer = [w for w in wheels if w.startswith("isobar_usd-")]
if len(core) != 1 or len(writer) != 1 or len(wheels) != 2:
    sys.exit(f"build.sh: expected one isobar and one isobar_usd wheel, found {wheels}")
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
