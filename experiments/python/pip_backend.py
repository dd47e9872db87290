"""`python3 -m pip install .`: a PEP 517 build backend (pyproject.toml names it) that builds the
`touchstone` module with the project's own CMake build and packs it as a wheel.

No third-party build tool is needed (the build requires nothing, so pip's isolated build
environment needs no network): CMake configures the source tree for the Python that runs pip
(-DPython_EXECUTABLE), builds the extension target `ts_python` and its libraries, and this file
writes the wheel (PEP 427) from what CMake laid out in BUILD/python/touchstone. The build folder
is $TS_BUILD_DIR when set (an existing build: only what changed is rebuilt), else build/pip in
the source tree. Every dependency comes from Debian (scripts/setup), as for the rest of the
project; the wheel is for this machine (its platform tag), not for PyPI.
"""
import base64
import hashlib
import os
import pathlib
import re
import subprocess
import sys
import sysconfig
import zipfile

NAME = "touchstone"
ROOT = pathlib.Path(__file__).resolve().parents[2]


def _version():
    text = (ROOT / "CMakeLists.txt").read_text()
    m = re.search(r"project\(touchstone VERSION ([0-9.]+)", text)
    if not m:
        raise RuntimeError("CMakeLists.txt: no `project(touchstone VERSION x.y.z` line")
    return m.group(1)


def _tag():
    """cpXY-cpXY-platform: the interpreter that runs pip, the extension's ABI, this platform."""
    interpreter = "cp%d%d" % sys.version_info[:2]
    platform = re.sub(r"[^a-zA-Z0-9]", "_", sysconfig.get_platform())
    return "%s-%s-%s" % (interpreter, interpreter, platform)


def _metadata():
    return ("Metadata-Version: 2.1\nName: %s\nVersion: %s\n"
            "Summary: Recognize a known object and localize it in 6 DOF from touch alone\n"
            "Requires-Python: >=3.9\nRequires-Dist: numpy\nLicense: see LICENSE\n") % (NAME, _version())


def _build():
    """Configure (once) and build the module; returns the folder holding the package."""
    build = pathlib.Path(os.environ.get("TS_BUILD_DIR") or ROOT / "build" / "pip").resolve()
    if not (build / "CMakeCache.txt").exists():
        subprocess.run(["cmake", "-S", str(ROOT), "-B", str(build), "-G", "Ninja", "-DCMAKE_BUILD_TYPE=Release",
                        "-DTS_PYTHON=ON", "-DPython_EXECUTABLE=" + sys.executable], check=True, stdout=sys.stderr)
    jobs = str(os.cpu_count() or 1)
    subprocess.run(["cmake", "--build", str(build), "--target", "ts_python", "-j", jobs], check=True,
                   stdout=sys.stderr)
    package = build / "python" / NAME
    built = sorted(package.glob("_touchstone*.so"))
    if not built:
        raise RuntimeError("no extension in %s after the build" % package)
    suffix = sysconfig.get_config_var("EXT_SUFFIX")
    if not any(p.name == "_touchstone" + suffix for p in built):
        raise RuntimeError("%s holds %s, not the extension for this Python (_touchstone%s): build with "
                           "this interpreter (TS_BUILD_DIR unset, or -DPython_EXECUTABLE=%s)"
                           % (package, ", ".join(p.name for p in built), suffix, sys.executable))
    return package, suffix


def _record_line(arcname, data):
    digest = base64.urlsafe_b64encode(hashlib.sha256(data).digest()).rstrip(b"=").decode()
    return "%s,sha256=%s,%d" % (arcname, digest, len(data))


def get_requires_for_build_wheel(config_settings=None):
    return []


def get_requires_for_build_sdist(config_settings=None):
    return []


def prepare_metadata_for_build_wheel(metadata_directory, config_settings=None):
    info = pathlib.Path(metadata_directory) / ("%s-%s.dist-info" % (NAME, _version()))
    info.mkdir(parents=True, exist_ok=True)
    (info / "METADATA").write_text(_metadata())
    return info.name


def build_wheel(wheel_directory, config_settings=None, metadata_directory=None):
    package, suffix = _build()
    version, tag = _version(), _tag()
    info = "%s-%s.dist-info" % (NAME, version)
    files = [(NAME + "/" + f, (package / f).read_bytes()) for f in ("__init__.py", "__init__.pyi", "py.typed")]
    files.append((NAME + "/_touchstone" + suffix, (package / ("_touchstone" + suffix)).read_bytes()))
    files.append((info + "/METADATA", _metadata().encode()))
    files.append((info + "/WHEEL", ("Wheel-Version: 1.0\nGenerator: touchstone pip_backend\nRoot-Is-Purelib: false\n"
                                    "Tag: %s\n" % tag).encode()))
    files.append((info + "/LICENSE", (ROOT / "LICENSE").read_bytes()))
    record = "\n".join(_record_line(a, d) for a, d in files) + "\n%s/RECORD,,\n" % info
    name = "%s-%s-%s.whl" % (NAME, version, tag)
    # Written under a temporary name and renamed when complete: never a half-written wheel.
    path = pathlib.Path(wheel_directory) / name
    tmp = path.with_name(name + ".part")
    with zipfile.ZipFile(tmp, "w", zipfile.ZIP_DEFLATED) as z:
        for arcname, data in files:
            z.writestr(arcname, data)
        z.writestr(info + "/RECORD", record)
    os.replace(tmp, path)
    return name


def build_sdist(sdist_directory, config_settings=None):
    raise RuntimeError("touchstone builds wheels from a source checkout only (`pip install .`); "
                       "for a source archive use `git archive`")
