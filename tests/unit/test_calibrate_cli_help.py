"""``shevsim calibrate MODEL --help``: the model's own columns, parameters and effects after the generic help.

The expectations are read from the code at test time (the column specs of :mod:`shevsim.calibrate.data`, the model
object of :func:`shevsim.calibrate.models.get_model`), so the help is checked against the model: an effect, a
column or a declared parameter missing from the help fails here."""
from __future__ import annotations

import pytest

from shevsim.calibrate.cli import main_calibrate
from shevsim.calibrate.data import OPTIONAL, REQUIRED, SIGNED
from shevsim.calibrate.models import MODELS, get_model


def _help(argv, capsys) -> str:
    assert main_calibrate(argv) == 0
    return capsys.readouterr().out


def _row(out: str, key: str) -> str:
    """The table row of ``key``, its wrapped continuation lines joined."""
    lines = out.splitlines()
    k = next(i for i, ln in enumerate(lines) if ln.startswith(f"  {key} "))
    indent = len(lines[k]) - len(lines[k].lstrip())
    rest = []
    for ln in lines[k + 1:]:
        if not ln.strip() or len(ln) - len(ln.lstrip()) <= indent:
            break
        rest.append(ln.strip())
    return " ".join([lines[k].strip()] + rest)


@pytest.mark.parametrize("name", sorted(MODELS))
def test_model_help_lists_the_models_columns_parameters_and_effects(name, capsys, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    out = _help([name, "--help"], capsys)
    assert "usage: shevsim calibrate" in out                      # the generic help first
    section = out[out.index(f"model {name}:"):]
    model = get_model(name, {}, "<params>")                       # as the command builds it without --params
    for col in REQUIRED[name] + OPTIONAL[name]:
        line = _row(section, col)
        assert ("required" if col in REQUIRED[name] else "optional") in line
        if col in model.inputs:
            assert "input" in line
        if col in model.channels + model.optional_channels:
            assert "fitted output" in line
        for option, signs in [SIGNED[name][col]] if col in SIGNED[name] else []:
            assert signs[0] in line and option in line
    for p in model.declared:
        assert p.name in section
    effects = list(model.effects) + ["timing"]                    # timing: added to every model by the workflow
    assert len(effects) >= 3
    for e in effects:
        assert f"\n  {e} " in section, f"effect {e} not in the help of {name}"
    assert f"shevsim calibrate {name} " in section.splitlines()[-1]
    assert list(tmp_path.iterdir()) == []                         # nothing written


def test_model_help_wherever_the_flag_is(capsys):
    assert "model cell:" in _help(["-h", "cell"], capsys)
    assert "model engine:" in _help(["engine", "data.csv", "--out", "x", "-h"], capsys)


def test_the_shevsim_command_routes_the_model_help(capsys):
    from shevsim.cli import main
    assert main(["calibrate", "vehicle", "--help"]) == 0
    out = capsys.readouterr().out
    assert "model vehicle:" in out and "mass_error" in out


def test_generic_help_points_to_the_model_help(capsys):
    with pytest.raises(SystemExit) as e:
        main_calibrate(["--help"])
    assert e.value.code == 0
    out = capsys.readouterr().out
    assert "MODEL --help" in " ".join(out.split())
    assert "candidate effects (" not in out and "model cell:" not in out
