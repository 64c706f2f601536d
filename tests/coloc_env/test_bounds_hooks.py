"""The bounds package records a play through the core's hooks, never by patching live objects."""

import ast
import importlib
import pathlib
import sys
import warnings

import numpy as np

import coloc_env
from coloc_env.bounds import record_play
from coloc_env.networks.base import DELIVERY_CALLS, Network
from coloc_env.parts import BACKENDS

PACKAGE = pathlib.Path(coloc_env.__file__).parent / "bounds"


class _Calls:
    def __init__(self):
        self.calls = []

    def readings(self, k, readings):
        pass

    def delivery(self, network, call, arguments, result):
        self.calls.append((call, dict(arguments)))


class _Doubling(Network):
    """A network that overrides two delivery calls, one calling the base's (reported once) and one not."""

    def broadcast(self, senders, listening, floats, slot=0):
        return super().broadcast(senders, listening, floats, slot)

    def packets(self, senders, listening, floats, slot=0):
        return np.zeros((self.batch, self.num_agents, self.num_agents), np.int64)


def test_a_network_subclass_reports_each_delivery_once_whatever_it_overrides():
    net = _Doubling(None, num_agents=3, batch=1, message_kind="broadcast")
    net.begin(np.zeros(1, int), np.zeros((1, 3, 2)), np.zeros((1, 3, 0), np.int64))
    calls = _Calls()
    net.observer = calls
    everyone = np.ones((1, 3), bool)
    heard = np.ones((1, 3, 3), bool)
    net.broadcast(everyone, heard, 2.0, slot=4)
    net.packets(everyone, heard, 1.0, 7)
    net.relay_each(np.array([[0, 1]]), np.array([[-1, 2]]), lambda h: 1.0, [0, 1])  # calls relay inside
    assert [c for c, _ in calls.calls] == ["broadcast", "packets", "relay_each"]
    assert calls.calls[0][1]["slot"] == 4 and calls.calls[1][1]["slot"] == 7  # named as Network names them
    net.observer = None
    net.broadcast(everyone, heard, 2.0)
    assert len(calls.calls) == 3
    for name in DELIVERY_CALLS:
        assert getattr(getattr(_Doubling, name), "reports_delivery", False), name


def test_relay_chains_are_recorded_as_the_network_resolved_them():
    spec = coloc_env.compose("circles", {"name": "relay", "loss_at_zero": 0.3}, "ukf_dcl", horizon=6)
    core = coloc_env.make_core(spec, batch=1)
    chains = []
    relay_each = type(core.network).relay_each

    class Spy(type(core.network)):  # the resolved chains as the backend sees them
        def relay_each(self, *args, **kwargs):
            out = relay_each(self, *args, **kwargs)
            chains.append((np.array(out.chain[0]), np.array(out.length[0])))
            return out

    core.network.__class__ = Spy
    record = record_play(core, np.random.default_rng(3), "always", None)
    recorded = [(e["chain"], e["length"]) for step in record.deliveries for e in step if e["call"] == "relay_each"]
    assert len(recorded) == len(chains) > 0
    for (chain, length), (seen, seen_length) in zip(recorded, chains, strict=True):
        np.testing.assert_array_equal(chain, seen)
        np.testing.assert_array_equal(length, seen_length)
    assert core.observer is None and core.network.observer is None and core.stand_in is None  # let go after the play


def _imports(tree):
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            yield node, [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):  # a name of a module may be a submodule: both listed
            yield node, [node.module or "", *(f"{node.module}.{a.name}" for a in node.names)]


def test_the_bounds_package_imports_at_top_level_only_and_never_the_package_root():
    for path in PACKAGE.rglob("*.py"):
        tree = ast.parse(path.read_text())
        top = {id(node) for node in tree.body}
        for node, names in _imports(tree):
            assert id(node) in top, f"{path}:{node.lineno}: an import inside a function"
            assert "coloc_env" not in names, f"{path}:{node.lineno}: import coloc_env"


def test_no_import_cycle_inside_the_bounds_package():
    modules = {}
    for path in PACKAGE.rglob("*.py"):
        name = ".".join(path.relative_to(PACKAGE.parent.parent).with_suffix("").parts).removesuffix(".__init__")
        modules[name] = {n for _, names in _imports(ast.parse(path.read_text())) for n in names
                         if n.startswith("coloc_env.bounds")}
    # a package's __init__ re-exporting its submodules is no cycle; a submodule importing back up would be
    graph = {m: {d for d in deps if d in modules and d != m and not m.startswith(d + ".")}
             for m, deps in modules.items()}
    state = {}

    def visit(node, path):
        state[node] = "open"
        for dep in graph[node]:
            assert state.get(dep) != "open", " -> ".join([*path, dep])
            if dep not in state:
                visit(dep, [*path, dep])
        state[node] = "done"

    for module in graph:
        if module not in state:
            visit(module, [module])


def test_the_old_bound_models_path_warns_and_still_imports():
    for name in [m for m in sys.modules if m.startswith("coloc_env.bound_models")]:
        del sys.modules[name]
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        old = importlib.import_module("coloc_env.bound_models")
        from coloc_env.bound_models import circles
    assert any(issubclass(w.category, DeprecationWarning) and "coloc_env.bounds.models" in str(w.message)
               for w in caught)
    assert circles is importlib.import_module("coloc_env.bounds.models.circles")
    assert old.SHARED_AT_LEADER == {name for name, cls in BACKENDS.items() if cls.shared_estimate}
