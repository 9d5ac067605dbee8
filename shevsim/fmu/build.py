"""build.py - build FMUs from sources: C (via fmpy's cmake helper) and Python (pythonfmu/pythonfmu3).

* :func:`build_c_fmu` - a directory with ``modelDescription.xml`` (FMI 2.0 with
  ``<SourceFiles>``, or FMI 3.0 with ``sources/buildDescription.xml``) and C
  sources -> a co-simulation FMU with a binary for this platform, compiled with
  fmpy's build helper (``fmpy.build.create_cmake_settings`` + fmpy's bundled
  CMakeLists.txt, i.e. what ``fmpy.build.build_platform_binary`` runs; cmake + gcc). fmpy
  needs an ABSOLUTE unzip directory; this function always passes one.
* :func:`build_python_fmu` - a pythonfmu (FMI 2.0) or pythonfmu3 (FMI 3.0)
  slave script -> FMU, built in a subprocess (the builders import the script
  and edit ``sys.path``; a subprocess keeps the caller clean). Python FMUs run
  in the Python that loads them (or the one found by the pythonfmu binary), so
  whatever the script imports must be installed there.

The sources shipped with shevsim live in ``fmus/src/<name>/`` (see ``fmus/README.md``).
"""
from __future__ import annotations

import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

from .errors import FMUError
from shevsim.core.paths import DATA_ROOT

__all__ = ["build_c_fmu", "build_python_fmu", "fmu_sources_dir", "repo_root"]


def repo_root() -> Path:
    """The directory holding the ``shevsim`` package (the repository root in a checkout)."""
    return DATA_ROOT


def fmu_sources_dir() -> Path:
    """``fmus/src`` of the repository."""
    return repo_root() / "fmus" / "src"


def python_env() -> dict[str, str]:
    env = dict(os.environ)
    root = str(repo_root())
    env["PYTHONPATH"] = root + (os.pathsep + env["PYTHONPATH"] if env.get("PYTHONPATH") else "")
    env["SHEVSIM_FMU_BUILD"] = "1"     # exported slave scripts skip their dependency check while built
    return env


def build_c_fmu(src_dir: str | Path, out_path: str | Path, build_dir: str | Path | None = None,
                keep_sources: bool = True) -> Path:
    """Compile a C-source FMU with fmpy's cmake build helper.

    Parameters
    ----------
    src_dir : path
        Directory with ``modelDescription.xml`` and the ``*.c``/``*.h`` files it
        lists (an optional ``buildDescription.xml`` goes to ``sources/``).
    out_path : path
        The ``.fmu`` file to write.
    build_dir : path, optional
        cmake build directory (a temporary one by default).
    keep_sources : bool
        Keep ``sources/`` inside the FMU (so other tools can rebuild it).

    Returns
    -------
    Path of the FMU. Raises :class:`FMUError` with the compiler output on failure.
    """
    from fmpy.build import create_cmake_settings
    from fmpy.util import create_zip_archive

    src_dir = Path(src_dir).absolute()
    out_path = Path(out_path).absolute()
    if not (src_dir / "modelDescription.xml").is_file():
        raise FMUError(f"{src_dir}: no modelDescription.xml")
    with tempfile.TemporaryDirectory(prefix="shevsim_cfmu_") as tmp:
        unzipdir = Path(tmp).absolute() / "fmu"
        sources = unzipdir / "sources"
        sources.mkdir(parents=True)
        shutil.copy2(src_dir / "modelDescription.xml", unzipdir / "modelDescription.xml")
        for f in src_dir.iterdir():
            if f.suffix in (".c", ".h") or f.name == "buildDescription.xml":
                shutil.copy2(f, sources / f.name)
        bdir = Path(build_dir).absolute() if build_dir else Path(tmp).absolute() / "build"
        bdir.mkdir(parents=True, exist_ok=True)
        # fmpy's helper writes the cmake cache (model identifier, sources, target dir
        # binaries/<platform>) for its bundled CMakeLists.txt; we run the two cmake
        # commands of fmpy.build.build_platform_binary ourselves to capture the output.
        import fmpy
        create_cmake_settings(unzipdir, bdir)
        cmake_src = (Path(fmpy.__file__).parent / "c-code").as_posix()
        for cmd in (["cmake", "-S", cmake_src, "-B", bdir.as_posix()],
                    ["cmake", "--build", bdir.as_posix(), "--target", "install", "--config", "Release"]):
            try:
                res = subprocess.run(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
            except FileNotFoundError as exc:
                raise FMUError(f"{src_dir}: cmake not found on PATH (needed to build C FMUs)") from exc
            if res.returncode:
                raise FMUError(f"{src_dir}: building the C FMU failed ({' '.join(cmd[:2])}):\n"
                               f"{res.stdout[-4000:]}")
        if not keep_sources:
            shutil.rmtree(sources)
        out_path.parent.mkdir(parents=True, exist_ok=True)
        if out_path.exists():
            out_path.unlink()
        create_zip_archive(out_path, unzipdir)
    return out_path


def build_python_fmu(script: str | Path, out_path: str | Path, fmi_version: int = 2,
                     handle_state: bool = True, project_files: tuple[str | Path, ...] = (),
                     timeout_s: float = 120.0) -> Path:
    """Build a pythonfmu (``fmi_version=2``) or pythonfmu3 (``3``) FMU from a slave script.

    The build runs ``python -m pythonfmu[3] build`` in a subprocess with the
    repository on ``PYTHONPATH`` (so scripts may import shevsim). With
    ``handle_state`` the FMU declares ``canGetAndSetFMUstate``.
    """
    script = Path(script).absolute()
    out_path = Path(out_path).absolute()
    if not script.is_file():
        raise FMUError(f"{script}: slave script not found")
    if fmi_version not in (2, 3):
        raise FMUError(f"fmi_version must be 2 or 3, got {fmi_version!r}")
    module = "pythonfmu" if fmi_version == 2 else "pythonfmu3"
    out_path.parent.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(prefix="shevsim_pyfmu_") as tmp:
        cmd = [sys.executable, "-m", module, "build", "-f", str(script), "-d", tmp]
        if handle_state:
            cmd.append("--handle-state")
        cmd += [str(Path(p).absolute()) for p in project_files]
        res = subprocess.run(cmd, cwd=tmp, env=python_env(), stdout=subprocess.PIPE,
                             stderr=subprocess.STDOUT, text=True, timeout=timeout_s)
        built = list(Path(tmp).glob("*.fmu"))
        if res.returncode or len(built) != 1:
            raise FMUError(f"{script}: {module} build failed (exit {res.returncode}):\n{res.stdout[-4000:]}")
        if out_path.exists():
            out_path.unlink()
        shutil.move(str(built[0]), out_path)
    return out_path


def reference_fmu_models() -> list[str]:
    """Models of the vendored Modelica Reference-FMUs sources (``fmus/src/reference_fmus``)."""
    root = fmu_sources_dir() / "reference_fmus"
    return sorted(p.name for p in root.iterdir() if (p / "model.c").is_file())


def build_reference_fmu(model: str, out_path: str | Path, fmi_version: int = 2,
                        interfaces: tuple[str, ...] = ("me", "cs"), drop_types: tuple[str, ...] = ()) -> Path:
    """Build one of the vendored Modelica Reference-FMUs (BSD-2, ``fmus/src/reference_fmus``).

    Parameters
    ----------
    model : str
        ``BouncingBall``, ``Dahlquist``, ``Feedthrough`` or ``StateSpace`` (FMI 3 only).
    out_path : path
        The ``.fmu`` to write.
    fmi_version : 2 or 3
    interfaces : tuple of {'me', 'cs'}
        Interfaces to keep in the model description; ``("me",)`` gives a model-exchange-only FMU
        (what Modelica tools export by default), ``("cs",)`` a co-simulation-only one.
    drop_types : tuple of str
        FMI 3 only: leave the variables of these types out of the model description
        (``("String", "Binary")`` turns ``Feedthrough`` into an FMU with numeric, integer
        and Boolean ports only; value references are unchanged, so the binary is the same).

    The template sources (``fmi2Functions.c``/``fmi3Functions.c``, ``cosimulation.c``) and the
    model's ``model.c``/``config.h`` are compiled as one translation unit ``all.c`` with
    ``FMI_VERSION`` defined, by :func:`build_c_fmu` (fmpy's cmake helper).
    """
    root = fmu_sources_dir() / "reference_fmus"
    src = root / model
    xml_file = src / f"FMI{fmi_version}.xml"
    if not (src / "model.c").is_file():
        raise FMUError(f"reference FMU '{model}' not found in {root} (have: {', '.join(reference_fmu_models())})")
    if not xml_file.is_file():
        raise FMUError(f"reference FMU '{model}' has no FMI {fmi_version} model description")
    bad = set(interfaces) - {"me", "cs"}
    if bad or not interfaces:
        raise FMUError(f"interfaces must be a non-empty subset of ('me', 'cs'), got {interfaces!r}")
    import re
    xml = xml_file.read_text()
    tags = {"me": "ModelExchange", "cs": "CoSimulation"}
    for key, tag in tags.items():
        if key not in interfaces:   # drop the element (self-closing or with children)
            xml = re.sub(rf"<{tag}\b[^>]*/>\s*|<{tag}\b.*?</{tag}>\s*", "", xml, count=1, flags=re.S)
    if drop_types:
        if fmi_version != 3:
            raise FMUError("drop_types needs FMI 3 (FMI 2 model structures refer to variables by index)")
        for typ in drop_types:
            vrs = re.findall(rf'<{typ}\b[^>]*valueReference="(\d+)"', xml)
            xml = re.sub(rf"<{typ}\b[^>]*/>\s*|<{typ}\b[^>]*[^/]>.*?</{typ}>\s*", "", xml, flags=re.S)
            for vr in vrs:
                xml = re.sub(rf'<(Output|InitialUnknown|ContinuousStateDerivative)\s+valueReference="{vr}"[^>]*/>\s*',
                             "", xml)
    with tempfile.TemporaryDirectory(prefix="shevsim_reffmu_") as tmp:
        d = Path(tmp)
        (d / "modelDescription.xml").write_text(xml)
        for f in (root / "template").iterdir():
            shutil.copy2(f, d / f.name)
        for f in ("model.c", "config.h"):
            shutil.copy2(src / f, d / f)
        (d / "all.c").write_text(f"#define FMI_VERSION {fmi_version}\n#define DISABLE_PREFIX\n"
                                 f'#include "fmi{fmi_version}Functions.c"\n#include "model.c"\n'
                                 f'#include "cosimulation.c"\n')
        if fmi_version == 3:
            (d / "buildDescription.xml").write_text(
                '<?xml version="1.0" encoding="UTF-8"?>\n<fmiBuildDescription fmiVersion="3.0">\n'
                f'  <BuildConfiguration modelIdentifier="{model}">\n    <SourceFileSet language="C99">\n'
                '      <SourceFile name="all.c"/>\n    </SourceFileSet>\n  </BuildConfiguration>\n'
                '</fmiBuildDescription>\n')
        else:
            # FMI 2 lists the sources in the model description; the template names all.c already
            if "<SourceFiles>" not in xml:
                raise FMUError(f"{xml_file}: no <SourceFiles> (expected all.c)")
        return build_c_fmu(d, out_path)
