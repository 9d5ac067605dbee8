"""No file a user hands us makes us import or execute code: component types come only from the registry
and installed entry-point plugins, never from a module path in a scenario (issue 13, item 1)."""
from __future__ import annotations

import subprocess
import sys
import textwrap

import pytest

from shevsim.components import REGISTRY, get_component_class, registered_types
from shevsim.core.errors import ScenarioError
from shevsim.core.scenario import build_master, load_scenario


def _scenario(type_name: str) -> str:
    return textwrap.dedent(f"""
        [scenario]
        name = "evil"
        stop_s = 1.0
        [components.x]
        type = "{type_name}"
    """)


@pytest.mark.parametrize("type_name", ["os:system", "this:x", "subprocess:Popen", "shevsim.components.verification:Gain",
                                       "evil_module_next_to_the_scenario:Thing", "os.path"])
def test_module_paths_are_refused_without_importing(type_name, tmp_path):
    (tmp_path / "evil_module_next_to_the_scenario.py").write_text("import sys; sys.modules['__evil_ran__'] = 1\n")
    f = tmp_path / "s.toml"
    f.write_text(_scenario(type_name))
    code = textwrap.dedent(f"""
        import sys
        sys.path.insert(0, {str(tmp_path)!r})
        from shevsim.core.scenario import build_master, load_scenario
        from shevsim.core.errors import ScenarioError
        try:
            build_master(load_scenario({str(f)!r}))
        except ScenarioError as exc:
            print("REFUSED", exc)
        print("this" in sys.modules, "__evil_ran__" in sys.modules, "evil_module_next_to_the_scenario" in sys.modules)
    """)
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    lines = r.stdout.strip().splitlines()
    assert lines[0].startswith("REFUSED") and "registered type" in lines[0] and "s.toml" in lines[0], lines
    assert lines[-1] == "False False False"          # nothing imported, nothing executed


def test_registered_names_and_plugins_are_the_only_way_in():
    assert set(REGISTRY) <= set(registered_types())
    assert get_component_class("battery").TYPE == "battery"
    with pytest.raises(ScenarioError, match="unknown component type 'baterry'.*did you mean 'battery'"):
        get_component_class("baterry")
    with pytest.raises(ScenarioError, match="registered name"):
        get_component_class(42)


def test_info_and_fmu_export_refuse_module_paths(tmp_path):
    from shevsim.fmu.export import resolve_component_class
    with pytest.raises(ScenarioError, match="module path"):
        resolve_component_class("os:system")
    f = tmp_path / "s.toml"
    f.write_text(_scenario("os:system"))
    with pytest.raises(ScenarioError, match="module path"):
        build_master(load_scenario(f))
