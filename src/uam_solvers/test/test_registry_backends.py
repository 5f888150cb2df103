"""Backend registry: lookup by name, listing, unknown names, entry points, the CLI."""
import pytest

import uam_solvers
from uam_solvers import registry
from uam_solvers.base import Backend, BackendUnavailable, MwisProblem, make_result

EXPECTED = {"greedy", "exact", "kamis", "chils", "gurobi", "sa", "tabu", "qpu", "qpu-emulator"}


def test_every_builtin_backend_is_listed_with_a_one_line_description():
    rows = {name: (desc, ok, reason) for name, desc, ok, reason in uam_solvers.list_backends()}
    assert EXPECTED <= set(rows)
    for name, (desc, ok, reason) in rows.items():
        assert desc and "\n" not in desc, name
        assert ok or reason, f"{name} unavailable without a reason"
    for name in ("greedy", "exact", "kamis", "chils"):
        assert rows[name][1], f"{name} should be available here: {rows[name][2]}"


def test_unknown_name_is_refused_listing_known_names():
    with pytest.raises(KeyError) as err:
        uam_solvers.get_backend("simulated-quantum")
    msg = str(err.value)
    assert "'simulated-quantum'" in msg
    for name in ("greedy", "exact", "chils", "qpu-emulator"):
        assert name in msg
    with pytest.raises(registry.UnknownBackendError):
        uam_solvers.solve([1.0], [], backend="nope")


def test_gurobi_without_gurobipy_is_listed_unavailable_and_solve_raises(monkeypatch):
    import builtins

    real_import = builtins.__import__

    def no_gurobi(name, *args, **kwargs):
        if name == "gurobipy" or name.startswith("gurobipy."):
            raise ImportError("No module named 'gurobipy'")
        return real_import(name, *args, **kwargs)

    monkeypatch.setattr(builtins, "__import__", no_gurobi)
    backend = uam_solvers.get_backend("gurobi")
    assert backend.available() == (False, "gurobipy is not installed")
    p = MwisProblem.from_arrays([1.0], [])
    with pytest.raises(BackendUnavailable, match="gurobipy is not installed"):
        backend.solve(p, time_limit_s=1.0, seed=0, options={})
    with pytest.raises(BackendUnavailable, match="gurobipy is not installed"):
        uam_solvers.solve([1.0], [], backend="gurobi")
    row = [r for r in uam_solvers.list_backends() if r[0] == "gurobi"][0]
    assert row[2:] == (False, "gurobipy is not installed")


class _PluginBackend(Backend):
    name = "plugin-first"
    description = "test plugin: picks vertex 0"

    def solve(self, problem, *, time_limit_s, seed, options):
        return make_result(problem, [0], proven_optimal=False, solve_time_s=0.0, backend=self.name)


def test_entry_point_backends_are_found_by_name(monkeypatch):
    monkeypatch.setattr(registry, "_entry_points",
                        lambda: {"plugin-first": f"{__name__}:_PluginBackend",
                                 "greedy": "not.used:Shadowed"})
    assert "plugin-first" in registry.backend_names()
    assert isinstance(registry.get_backend("plugin-first"), _PluginBackend)
    assert type(registry.get_backend("greedy")).__name__ == "GreedyBackend"  # built-in wins
    r = uam_solvers.solve([1.0, 1.0], [[0, 1]], backend="plugin-first")
    assert r.selected.tolist() == [0] and r.backend == "plugin-first"


def test_cli_prints_one_line_per_backend(capsys):
    assert registry.main([]) == 0
    lines = capsys.readouterr().out.strip().splitlines()
    names = [line.split()[0] for line in lines]
    assert EXPECTED <= set(names)
    assert any(line.startswith("greedy") and "[available]" in line for line in lines)
    assert registry.main(["bogus"]) == 2


class _PluginSampler:
    """A third party's sampling backend, as an entry point would name it (traits only here)."""

    samples = True


def test_a_sampler_is_known_as_one_everywhere_by_its_class_alone(monkeypatch):
    from uam_solvers import registry
    from uam_solvers.tts import ANNEALING_BACKENDS  # derived from the registry at import

    assert set(registry.sampling_backends()) == set(ANNEALING_BACKENDS) == {"sa", "tabu", "qpu", "qpu-emulator"}
    assert not registry.backend_class("exact").samples and registry.backend_class("sa").samples
    monkeypatch.setattr(registry, "_entry_points", lambda: {"plugin-sampler": f"{__name__}:_PluginSampler"})
    assert "plugin-sampler" in registry.sampling_backends()
