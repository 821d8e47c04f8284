"""In-tree PEP 517 / PEP 660 build backend of the `isobar` Python package.

Builds the Rust core with cargo and writes a wheel whose package carries libisobar.so.
Standard library only, so `pip install ./rust-core/python` needs no index for the build.

Hooks: build_wheel, build_editable, build_sdist and the get_requires_* hooks (nothing
required). The wheel is tagged py3-none-<platform> because the package is pure Python over
ctypes but ships a native library built for this platform.

Environment:
  CARGO                   the cargo executable (default: `cargo` on PATH, then ~/.cargo/bin)
  ISOBAR_CRATE_DIR        the crate folder (default: the folder above this package source)
  ISOBAR_PREBUILT_LIBRARY a libisobar.so to bundle as it is; no cargo run
  ISOBAR_STRIP            0 to keep the library's debug info (default: strip --strip-debug)
"""

from __future__ import annotations

import base64
import hashlib
import io
import json
import os
import re
import shutil
import subprocess
import sys
import sysconfig
import tarfile
import tempfile
import zipfile
from pathlib import Path

SOURCE = Path(__file__).resolve().parent.parent  # rust-core/python
PACKAGE = "isobar"
LIBRARY = "libisobar.so"

SUMMARY = "Exact isosurfaces of SPH particle data (ctypes over the isobar core)"
REQUIRES_PYTHON = ">=3.9"
REQUIRES = ["numpy>=1.21"]
EXTRAS = {"pyvista": ["pyvista>=0.43"]}
LICENSE = "MIT OR Apache-2.0"

# Fixed timestamp for reproducible archives (or SOURCE_DATE_EPOCH).
_EPOCH = int(os.environ.get("SOURCE_DATE_EPOCH", "315532800"))  # 1980-01-01


def _version() -> str:
    text = (SOURCE / PACKAGE / "_version.py").read_text(encoding="utf-8")
    match = re.search(r'^__version__\s*=\s*"([^"]+)"', text, re.M)
    if not match:
        raise RuntimeError("isobar/_version.py has no __version__ = \"...\" line")
    return match.group(1)


def _log(message: str) -> None:
    print(f"isobar build: {message}", file=sys.stderr, flush=True)


# ----------------------------------------------------------------------------------------
# The native library


def _crate_dir() -> Path:
    crate = Path(os.environ.get("ISOBAR_CRATE_DIR", SOURCE.parent)).resolve()
    manifest = crate / "Cargo.toml"
    if not manifest.is_file() or not re.search(r'^name\s*=\s*"isobar"', manifest.read_text(encoding="utf-8"), re.M):
        raise RuntimeError(
            f"no isobar crate at {crate} (looked for Cargo.toml with name = \"isobar\"); "
            "build from the repository (pip install ./rust-core/python), set ISOBAR_CRATE_DIR "
            "to the crate folder, or ISOBAR_PREBUILT_LIBRARY to a built libisobar.so"
        )
    return crate


def _cargo() -> str:
    explicit = os.environ.get("CARGO")
    if explicit:
        return explicit
    found = shutil.which("cargo")
    if found:
        return found
    home = Path.home() / ".cargo" / "bin" / "cargo"
    if home.is_file():
        return str(home)
    raise RuntimeError("cargo not found: building isobar needs a Rust toolchain (rustup); or set ISOBAR_PREBUILT_LIBRARY")


def _cargo_build() -> Path:
    """Runs cargo and returns the path of the cdylib it reports."""
    crate = _crate_dir()
    cmd = [
        _cargo(),
        "build",
        "--release",
        "--lib",
        "-p",
        "isobar",
        "--manifest-path",
        str(crate / "Cargo.toml"),
        "--message-format=json-render-diagnostics",
    ]
    _log(" ".join(cmd))
    proc = subprocess.run(cmd, stdout=subprocess.PIPE, text=True, cwd=crate)  # stderr: the user's
    if proc.returncode != 0:
        raise RuntimeError(f"cargo build failed (exit {proc.returncode}); see the messages above")
    library = None
    for line in proc.stdout.splitlines():
        try:
            message = json.loads(line)
        except ValueError:
            continue
        if message.get("reason") != "compiler-artifact":
            continue
        target = message.get("target", {})
        if target.get("name") != "isobar" or "cdylib" not in target.get("kind", []):
            continue
        for name in message.get("filenames", []):
            if name.endswith(".so"):
                library = Path(name)
    if library is None or not library.is_file():
        raise RuntimeError("cargo reported no libisobar.so (is crate-type cdylib still set?)")
    return library


def _library(workdir: Path) -> Path:
    """The library to bundle: prebuilt or freshly built, stripped copy in `workdir`."""
    prebuilt = os.environ.get("ISOBAR_PREBUILT_LIBRARY")
    built = Path(prebuilt).resolve() if prebuilt else _cargo_build()
    if not built.is_file():
        raise RuntimeError(f"ISOBAR_PREBUILT_LIBRARY={prebuilt} is not a file")
    copy = workdir / LIBRARY
    shutil.copyfile(built, copy)
    if os.environ.get("ISOBAR_STRIP", "1") != "0":
        strip = shutil.which("strip")
        if strip:
            result = subprocess.run([strip, "--strip-debug", str(copy)], capture_output=True, text=True)
            if result.returncode != 0:
                _log(f"strip failed, bundling the library unstripped: {result.stderr.strip()}")
    _log(f"bundling {built} ({copy.stat().st_size} bytes)")
    return copy


# ----------------------------------------------------------------------------------------
# Metadata and wheel writing


def _platform_tag() -> str:
    return re.sub(r"[^A-Za-z0-9]", "_", sysconfig.get_platform())


def _metadata() -> str:
    lines = [
        "Metadata-Version: 2.1",
        f"Name: {PACKAGE}",
        f"Version: {_version()}",
        f"Summary: {SUMMARY}",
        f"License: {LICENSE}",
        f"Requires-Python: {REQUIRES_PYTHON}",
    ]
    lines += [f"Requires-Dist: {r}" for r in REQUIRES]
    for extra, reqs in EXTRAS.items():
        lines.append(f"Provides-Extra: {extra}")
        lines += [f'Requires-Dist: {r}; extra == "{extra}"' for r in reqs]
    readme = SOURCE / "README.md"
    lines.append("Description-Content-Type: text/markdown")
    text = "\n".join(lines) + "\n\n"
    if readme.is_file():
        text += readme.read_text(encoding="utf-8")
    return text


def _wheel_file(tag: str) -> str:
    return f"Wheel-Version: 1.0\nGenerator: isobar-backend\nRoot-Is-Purelib: false\nTag: {tag}\n"


def _record_hash(data: bytes) -> str:
    digest = base64.urlsafe_b64encode(hashlib.sha256(data).digest()).rstrip(b"=").decode()
    return f"sha256={digest}"


class _Wheel:
    def __init__(self, path: Path):
        self.zip = zipfile.ZipFile(path, "w", compression=zipfile.ZIP_DEFLATED)
        self.records: list[str] = []

    def add(self, arcname: str, data: bytes, executable: bool = False) -> None:
        info = zipfile.ZipInfo(arcname, date_time=_zip_time())
        info.external_attr = ((0o100755 if executable else 0o100644) & 0xFFFF) << 16
        info.compress_type = zipfile.ZIP_DEFLATED
        self.zip.writestr(info, data)
        self.records.append(f"{arcname},{_record_hash(data)},{len(data)}")

    def close(self, record_name: str) -> None:
        self.records.append(f"{record_name},,")
        info = zipfile.ZipInfo(record_name, date_time=_zip_time())
        info.external_attr = 0o100644 << 16
        self.zip.writestr(info, "\n".join(self.records) + "\n")
        self.zip.close()


def _zip_time():
    import time

    return time.gmtime(max(_EPOCH, 315532800))[:6]


def _package_files() -> list[Path]:
    return sorted(p for p in (SOURCE / PACKAGE).rglob("*") if p.is_file() and p.suffix in (".py", ".typed"))


def _write_wheel(wheel_directory: str, editable: bool) -> str:
    version = _version()
    tag = f"py3-none-{_platform_tag()}"
    name = f"{PACKAGE}-{version}-{tag}.whl"
    dist_info = f"{PACKAGE}-{version}.dist-info"
    out = Path(wheel_directory) / name
    with tempfile.TemporaryDirectory() as tmp:
        if not editable:
            library = _library(Path(tmp))
        elif not os.environ.get("ISOBAR_PREBUILT_LIBRARY"):
            _cargo_build()  # so that the tree's target/release library is current
        wheel = _Wheel(out)
        try:
            if editable:
                # The source package imports from the tree; _lib finds the library in
                # the workspace's target/release (or ISOBAR_LIBRARY).
                wheel.add(f"_{PACKAGE}_editable.pth", (str(SOURCE) + "\n").encode())
            else:
                for path in _package_files():
                    arc = path.relative_to(SOURCE).as_posix()
                    wheel.add(arc, path.read_bytes())
                wheel.add(f"{PACKAGE}/{LIBRARY}", library.read_bytes(), executable=True)
            wheel.add(f"{dist_info}/METADATA", _metadata().encode())
            wheel.add(f"{dist_info}/WHEEL", _wheel_file(tag).encode())
            wheel.add(f"{dist_info}/top_level.txt", f"{PACKAGE}\n".encode())
        finally:
            wheel.close(f"{dist_info}/RECORD")
    _log(f"wrote {out}")
    return name


# ----------------------------------------------------------------------------------------
# PEP 517 / 660 hooks


def get_requires_for_build_wheel(config_settings=None):
    """Nothing beyond the standard library (cargo must be on PATH)."""
    return []


def get_requires_for_build_sdist(config_settings=None):
    """Nothing beyond the standard library."""
    return []


def get_requires_for_build_editable(config_settings=None):
    """Nothing beyond the standard library."""
    return []


def _prepare_metadata(metadata_directory) -> str:
    dist_info = f"{PACKAGE}-{_version()}.dist-info"
    target = Path(metadata_directory) / dist_info
    target.mkdir(parents=True, exist_ok=True)
    (target / "METADATA").write_text(_metadata(), encoding="utf-8")
    (target / "WHEEL").write_text(_wheel_file(f"py3-none-{_platform_tag()}"), encoding="utf-8")
    (target / "top_level.txt").write_text(f"{PACKAGE}\n", encoding="utf-8")
    return dist_info


def prepare_metadata_for_build_wheel(metadata_directory, config_settings=None):
    """Writes the dist-info folder without building the library."""
    return _prepare_metadata(metadata_directory)


def prepare_metadata_for_build_editable(metadata_directory, config_settings=None):
    """Writes the dist-info folder without building the library."""
    return _prepare_metadata(metadata_directory)


def build_wheel(wheel_directory, config_settings=None, metadata_directory=None):
    """Builds the core with cargo and writes a platform wheel carrying libisobar.so."""
    return _write_wheel(wheel_directory, editable=False)


def build_editable(wheel_directory, config_settings=None, metadata_directory=None):
    """Builds the core and writes a wheel whose .pth points at the source package."""
    return _write_wheel(wheel_directory, editable=True)


def build_sdist(sdist_directory, config_settings=None):
    """Writes the Python sources only; building a wheel from it needs ISOBAR_CRATE_DIR
    (the Rust crate) or ISOBAR_PREBUILT_LIBRARY."""
    version = _version()
    base = f"{PACKAGE}-{version}"
    name = f"{base}.tar.gz"
    files = [SOURCE / "pyproject.toml", SOURCE / "README.md", SOURCE / "_build" / "backend.py"] + _package_files()
    with tarfile.open(Path(sdist_directory) / name, "w:gz", format=tarfile.PAX_FORMAT) as tar:
        for path in files:
            if not path.is_file():
                continue
            data = path.read_bytes()
            info = tarfile.TarInfo(f"{base}/{path.relative_to(SOURCE).as_posix()}")
            info.size, info.mtime, info.mode = len(data), _EPOCH, 0o644
            tar.addfile(info, io.BytesIO(data))
        pkg_info = _metadata().encode()
        info = tarfile.TarInfo(f"{base}/PKG-INFO")
        info.size, info.mtime, info.mode = len(pkg_info), _EPOCH, 0o644
        tar.addfile(info, io.BytesIO(pkg_info))
    return name
