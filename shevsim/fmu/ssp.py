"""ssp.py - a scenario as an SSP package (System Structure and Parameterization 1.0) and back.

:func:`export_ssp` writes ``NAME.ssp``, a ZIP holding

* ``resources/<component>.fmu`` - every component as an FMI 2.0 co-simulation FMU: native components
  exported with :func:`shevsim.fmu.export.export_component` (self-contained, with the parameters
  the scenario gives them - files, ``set`` overrides and the derived noise seed - and their
  ``step_multiple`` built in: the FMU steps over ``k`` communication steps every ``k``-th ``doStep``),
  FMU components copied as they are;
* ``SystemStructure.ssd`` - the components with their connectors (inputs/outputs, typed Real), the
  connections, the numeric parameters of each component as inline ``ssv:ParameterSet`` bindings
  (documentation for other tools: the values are also the FMUs' start values), the default
  experiment (start and stop time), and a ``shevsim`` annotation with the communication step,
  method and execution order (SSP itself has no notion of either).

fmpy's ``fmpy.ssp.simulation.simulate_ssp`` runs it (FMI 2.0 co-simulation, one step size; its
master is a Jacobi iteration whose connectors start at 0.0). :func:`import_ssp` extracts an SSP
into a folder and writes a scenario TOML there (``type = "fmu"`` components, connections, parameter
bindings as ``set``, step/method/order from the shevsim annotation when present).

CLI: ``shevsim fmu export-ssp SCENARIO -o OUT.ssp`` and ``shevsim fmu import-ssp IN.ssp -o FOLDER``.
"""
from __future__ import annotations

import dataclasses
import json
import math
import shutil
import tempfile
import zipfile
from pathlib import Path
from typing import Any
from xml.etree import ElementTree as ET

from ..core.errors import ScenarioError
from ..core.tomlio import toml_key, toml_value
from .errors import FMUError

__all__ = ["export_ssp", "import_ssp", "NS"]

NS = {"ssd": "http://ssp-standard.org/SSP1/SystemStructureDescription",
      "ssc": "http://ssp-standard.org/SSP1/SystemStructureCommon",
      "ssv": "http://ssp-standard.org/SSP1/SystemStructureParameterValues"}
_ANN = "org.shevsim"
_SHEVSIM_NS = "urn:shevsim:ssp"
ET.register_namespace("shevsim", _SHEVSIM_NS)
for _k, _v in NS.items():
    ET.register_namespace(_k, _v)


def _q(prefix: str, tag: str) -> str:
    return f"{{{NS[prefix]}}}{tag}"


def _numeric_params(params) -> dict[str, Any]:
    if params is None or not dataclasses.is_dataclass(params):
        return {}
    out = {}
    for f in dataclasses.fields(params):
        v = getattr(params, f.name)
        if isinstance(v, (bool, int, float)) and math.isfinite(v):
            out[f.name] = v
    return out


def _param_xml(parent, values: dict[str, Any]) -> None:
    if not values:
        return
    pb = ET.SubElement(ET.SubElement(parent, _q("ssd", "ParameterBindings")), _q("ssd", "ParameterBinding"))
    pv = ET.SubElement(pb, _q("ssd", "ParameterValues"))
    ps = ET.SubElement(pv, _q("ssv", "ParameterSet"), version="1.0", name="parameters")
    plist = ET.SubElement(ps, _q("ssv", "Parameters"))
    for name, v in values.items():
        p = ET.SubElement(plist, _q("ssv", "Parameter"), name=name)
        if isinstance(v, bool):
            ET.SubElement(p, _q("ssv", "Boolean"), value="true" if v else "false")
        elif isinstance(v, int):
            ET.SubElement(p, _q("ssv", "Integer"), value=str(v))
        else:
            ET.SubElement(p, _q("ssv", "Real"), value=repr(float(v)))


def export_ssp(scenario, out_path: str | Path, stop_s: float | None = None, sets: tuple[str, ...] = (),
               force: bool = False) -> Path:
    """Export a scenario (path, bundled name or :class:`~shevsim.core.scenario.Scenario`) as an SSP package.

    Parameters
    ----------
    scenario : path, name or Scenario
    out_path : path of the ``.ssp`` to write
    stop_s : float, optional
        Stop time of the default experiment (default: the scenario's).
    sets : ``--set`` style overrides applied when loading a scenario file.
    force : replace ``out_path`` when it exists (default: an existing file is refused, not overwritten).

    Returns the path written. Components must be native components or FMI 2.0 co-simulation FMUs
    (what fmpy's SSP runner takes); inputs given start values in the scenario are written as
    parameter bindings of the input variables.
    """
    from ..core.scenario import Scenario, build_master, load_scenario, stop_time
    from .adapter import FMUComponent
    from .export import export_component
    from ..core.atomic import refuse_overwrite
    refuse_overwrite(out_path, force)

    sc = scenario if isinstance(scenario, Scenario) else load_scenario(scenario, list(sets))
    out_path = Path(out_path).absolute()
    m = build_master(sc)
    try:
        stop = float(stop_s) if stop_s is not None else float(stop_time(sc, m))
        root = ET.Element(_q("ssd", "SystemStructureDescription"), version="1.0", name=sc.name)
        system = ET.SubElement(root, _q("ssd", "System"), name=sc.name)
        elements = ET.SubElement(system, _q("ssd", "Elements"))
        with tempfile.TemporaryDirectory(prefix="shevsim_ssp_") as tmp:
            tmp = Path(tmp)
            (tmp / "resources").mkdir()
            for name in m.order:
                comp = m.components[name]
                fmu_file = tmp / "resources" / f"{name}.fmu"
                spec = next(s for s in sc.components if s.name == name)
                values: dict[str, Any] = {}
                if isinstance(comp, FMUComponent):
                    if comp.fmi_version != "2.0" or comp.kind != "cs":
                        raise FMUError(f"export-ssp: component '{name}' is an FMI {comp.fmi_version} "
                                       f"{'model-exchange' if comp.kind == 'me' else 'co-simulation'} FMU; "
                                       f"the SSP runner (fmpy) takes FMI 2.0 co-simulation FMUs")
                    if m.step_multiples[name] != 1:
                        raise FMUError(f"export-ssp: FMU component '{name}' has step_multiple "
                                       f"{m.step_multiples[name]}; only native components can carry one")
                    shutil.copy2(comp.path, fmu_file)
                    values = {k: v for k, v in comp.params.items() if isinstance(v, (bool, int, float))}
                else:
                    export_component(type(comp), None, fmu_file, fmi_version=2, params=comp.params,
                                     step_multiple=m.step_multiples[name], start_values=dict(spec.start),
                                     model_name=f"Shevsim_{sc.name}_{name}".replace("-", "_"))
                    ports = {v.name for v in comp.variables() if v.causality in ("input", "output")}
                    values = {k: v for k, v in _numeric_params(comp.params).items() if k not in ports}
                el = ET.SubElement(elements, _q("ssd", "Component"), name=name,
                                   type="application/x-fmu-sharedlibrary", source=f"resources/{name}.fmu")
                conns = ET.SubElement(el, _q("ssd", "Connectors"))
                # connected inputs and every output (an SSP runner writes every input connector it is
                # given - fmpy writes 0.0 to unconnected ones - so unconnected inputs keep the FMU's start)
                connected = {c.dst_port for c in m.connections if c.dst == name}
                for v in comp.variables():
                    if v.causality == "output" or (v.causality == "input" and v.name in connected):
                        c = ET.SubElement(conns, _q("ssd", "Connector"), name=v.name, kind=v.causality)
                        ET.SubElement(c, _q("ssc", "Real"))
                _param_xml(el, values)
            cons = ET.SubElement(system, _q("ssd", "Connections"))
            for c in m.connections:
                ET.SubElement(cons, _q("ssd", "Connection"), startElement=c.src, startConnector=c.src_port,
                              endElement=c.dst, endConnector=c.dst_port)
            ann = ET.SubElement(ET.SubElement(system, _q("ssd", "Annotations")), _q("ssc", "Annotation"),
                                type=_ANN)
            ET.SubElement(ann, f"{{{_SHEVSIM_NS}}}Settings", json=json.dumps(
                {"step_s": sc.settings.step_s, "method": sc.settings.method, "order": list(m.order),
                 "step_multiples_built_in": dict(m.step_multiples), "t0_s": sc.t0_s, "seed": sc.seed}))
            ET.SubElement(root, _q("ssd", "DefaultExperiment"), startTime=repr(float(sc.t0_s)), stopTime=repr(stop))
            ET.ElementTree(root).write(tmp / "SystemStructure.ssd", xml_declaration=True, encoding="UTF-8")
            out_path.parent.mkdir(parents=True, exist_ok=True)
            part = out_path.with_name(out_path.name + ".part")
            try:
                with zipfile.ZipFile(part, "w", zipfile.ZIP_DEFLATED) as zf:
                    zf.write(tmp / "SystemStructure.ssd", "SystemStructure.ssd")
                    for f in sorted((tmp / "resources").iterdir()):
                        zf.write(f, f"resources/{f.name}")
                part.replace(out_path)
            finally:
                part.unlink(missing_ok=True)
    finally:
        m.terminate()
    return out_path


_HEADER = "# imported from an SSP package by shevsim.fmu.ssp.import_ssp"


def import_ssp(ssp_path: str | Path, out_dir: str | Path, step_s: float | None = None) -> Path:
    """Extract an SSP into ``out_dir`` and write ``out_dir/<system>.toml``, a scenario running it.

    Parameters
    ----------
    ssp_path : the ``.ssp`` file
    out_dir : folder to write into; files of the names it writes are replaced only when they come
        from an earlier import (else a ScenarioError: nothing a user wrote is overwritten)
    step_s : communication step; default: the shevsim annotation's, else 1/100 of the stop time

    Returns the scenario path. Errors name the SSP file and the element.
    """
    ssp_path = Path(ssp_path)
    out_dir = Path(out_dir)
    if not ssp_path.is_file():
        raise ScenarioError(f"{ssp_path}: SSP file not found")
    if not zipfile.is_zipfile(ssp_path):
        raise ScenarioError(f"{ssp_path}: not an SSP package (not a ZIP archive)")
    with zipfile.ZipFile(ssp_path) as zf:
        from .adapter import MAX_MODEL_DESCRIPTION_BYTES, check_archive
        check_archive(zf, ssp_path, "SSP", ScenarioError, {"SystemStructure.ssd": MAX_MODEL_DESCRIPTION_BYTES})
        names = zf.namelist()
        if "SystemStructure.ssd" not in names:
            raise ScenarioError(f"{ssp_path}: no SystemStructure.ssd in the package")
        for n in names:                        # no absolute paths or '..' out of the folder
            if n.startswith("/") or ".." in Path(n).parts:
                raise ScenarioError(f"{ssp_path}: unsafe member path '{n}'")
        try:
            root = ET.fromstring(zf.read("SystemStructure.ssd"))
        except ET.ParseError as exc:
            raise ScenarioError(f"{ssp_path}: SystemStructure.ssd is not well-formed XML: {exc}") from exc
        system = root.find("ssd:System", NS)
        if system is None:
            raise ScenarioError(f"{ssp_path}: SystemStructure.ssd has no <ssd:System>")
        sysname = system.get("name") or root.get("name") or ssp_path.stem
        comps = _ssp_components(system, names, ssp_path)
        if not comps:
            raise ScenarioError(f"{ssp_path}: the system has no components")
        conns = []
        for c in system.findall("ssd:Connections/ssd:Connection", NS):
            conns.append((c.get("endElement"), c.get("endConnector"), c.get("startElement"), c.get("startConnector")))
        meta = {}
        for a in system.findall("ssd:Annotations/ssc:Annotation", NS):
            node = a.find(f"{{{_SHEVSIM_NS}}}Settings")
            if a.get("type") == _ANN and node is not None and node.get("json"):
                meta = json.loads(node.get("json"))
        de = root.find("ssd:DefaultExperiment", NS)
        t0 = float(de.get("startTime", 0.0)) if de is not None else 0.0
        stop = float(de.get("stopTime")) if de is not None and de.get("stopTime") else None
        _extract_fmus(zf, ssp_path, out_dir, sysname, comps)
    step = step_s or meta.get("step_s") or ((stop - t0) / 100.0 if stop else None)
    if not step:
        raise ScenarioError(f"{ssp_path}: no communication step (no shevsim annotation and no stop time): "
                            f"give step_s")
    lines = _scenario_lines(sysname, step, t0, stop, meta, comps, conns)
    scen = out_dir / f"{sysname}.toml"
    scen.write_text("\n".join(lines) + "\n")
    return scen


def _ssp_components(system, names: list[str], ssp_path: Path) -> list[tuple[str, str, dict]]:
    """The system's FMU components: ``(name, source in the package, bound parameter values)``."""
    comps = []
    for el in system.findall("ssd:Elements/ssd:Component", NS):
        name, source = el.get("name"), el.get("source") or ""
        if not name or not source.endswith(".fmu"):
            raise ScenarioError(f"{ssp_path}: component '{name}': only FMU components are supported "
                                f"(source '{source}')")
        if source not in names:
            raise ScenarioError(f"{ssp_path}: component '{name}': source '{source}' is not in the package")
        params = {}
        for p in el.findall("ssd:ParameterBindings/ssd:ParameterBinding/ssd:ParameterValues/"
                            "ssv:ParameterSet/ssv:Parameters/ssv:Parameter", NS):
            for typ in ("Real", "Integer", "Boolean"):
                node = p.find(f"ssv:{typ}", NS)
                if node is not None:
                    val = node.get("value")
                    params[p.get("name")] = (float(val) if typ == "Real" else int(val) if typ == "Integer"
                                             else val.strip().lower() == "true")
        comps.append((name, source, params))
    return comps


def _extract_fmus(zf, ssp_path: Path, out_dir: Path, sysname: str, comps) -> None:
    """Write each component's FMU into ``out_dir``, refusing files there an earlier import did not write."""
    out_dir.mkdir(parents=True, exist_ok=True)
    # never overwrite what a user wrote: files of the same names are replaced only when the
    # folder holds a previous import (its scenario file starts with our header)
    scen_file = out_dir / f"{sysname}.toml"
    ours = scen_file.is_file() and scen_file.read_text(errors="replace").startswith(_HEADER)
    clash = [f.name for f in [scen_file] + [out_dir / f"{n}.fmu" for n, _, _ in comps] if f.exists()]
    if clash and not ours:
        raise ScenarioError(f"{ssp_path}: {out_dir} already holds {', '.join(clash)} (not from an earlier "
                            f"import); choose another folder")
    for name, source, _ in comps:
        (out_dir / f"{name}.fmu").write_bytes(zf.read(source))


def _scenario_lines(sysname: str, step: float, t0: float, stop: float | None, meta: dict, comps,
                    conns) -> list[str]:
    """The scenario TOML that runs the imported system (header first: marks a file as ours)."""
    lines = [_HEADER, "[scenario]",
             f"name = {toml_value(sysname)}", f"step_s = {step!r}",
             f"method = {toml_value(meta.get('method', 'jacobi'))}", f"t0_s = {t0!r}"]
    if stop is not None:
        lines.append(f"stop_s = {stop!r}")
    if meta.get("order"):
        lines.append("order = [" + ", ".join(toml_value(n) for n in meta["order"]) + "]")
    if "seed" in meta:
        lines.append(f"seed = {int(meta['seed'])}")
    for name, _, params in comps:
        lines += ["", f"[components.{toml_key(name)}]", 'type = "fmu"', f"fmu = {toml_value(name + '.fmu')}"]
        if params:
            lines.append("set = { " + ", ".join(f"{toml_key(k)} = {toml_value(v)}" for k, v in params.items())
                         + " }")
    lines += ["", "[connections]"]
    for dst, dport, src, sport in conns:
        lines.append(f"{toml_value(dst + '.' + dport)} = {toml_value(src + '.' + sport)}")
    return lines
