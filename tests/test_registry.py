"""Method registry: spec parsing, type coercion, create(), errors, and plugins through entry points."""

from __future__ import annotations

import inspect
from pathlib import Path
from typing import Literal, Optional

import numpy as np
import pytest
from helpers import forget_module, install_fake_plugin, write_scene

import lfbench.method.registry as registry
from lfbench.data.hci import HCIScene
from lfbench.data.scene import ArrayLightField
from lfbench.method.base import Method, Prediction
from lfbench.method.registry import MethodRegistry, Param, coerce, format_spec, parse_spec, register_method
from lfbench.utils.errors import SpecError

# --------------------------------------------------------------------------- spec strings


@pytest.mark.parametrize("spec, expected", [
    ("gt", ("gt", {})),
    ("  planesweep  ", ("planesweep", {})),
    ("planesweep:", ("planesweep", {})),
    ("planesweep:interval=0.01,mode=bilinear", ("planesweep", {"interval": "0.01", "mode": "bilinear"})),
    ("published:path=/data/pub/subfocal", ("published", {"path": "/data/pub/subfocal"})),
    ("a.b-c_d:k = v , x=", ("a.b-c_d", {"k": "v", "x": ""})),
    ("m:expr=a=b", ("m", {"expr": "a=b"})),
])
def test_parse_spec(spec, expected):
    assert parse_spec(spec) == expected


@pytest.mark.parametrize("spec, fragment", [
    ("", "bad method spec"),
    (":k=v", "bad method spec"),
    ("two words", "bad method spec"),
    ("m:k", "'k' is not key=value"),
    ("m:1k=2", "is not key=value"),
    ("m:k=1,k=2", "'k' given twice"),
    ("m:k=1,,j=2", "is not key=value"),
])
def test_parse_spec_errors(spec, fragment):
    with pytest.raises(SpecError, match=fragment):
        parse_spec(spec)


def test_format_spec_inverts_parse_spec():
    assert format_spec("m", {}) == "m"
    assert parse_spec(format_spec("m", {"a": 1, "b": "x"})) == ("m", {"a": "1", "b": "x"})


# --------------------------------------------------------------------------- coercion


def _p(kind, default=inspect.Parameter.empty) -> Param:
    return Param("x", kind, default)


@pytest.mark.parametrize("kind, text, expected", [
    (bool, "true", True), (bool, "Yes", True), (bool, "1", True), (bool, "on", True),
    (bool, "false", False), (bool, "NO", False), (bool, "0", False), (bool, "off", False),
    (int, "42", 42), (int, "-3", -3),
    (float, "0.25", 0.25), (float, "1e-3", 1e-3), (float, "-2", -2.0),
    (str, "hello", "hello"),
    (Path, "/a/b", Path("/a/b")),
    (Optional[int], "none", None), (Optional[int], "None", None), (Optional[int], "7", 7),  # noqa: UP045
    (int | None, "", None), (float | None, "0.5", 0.5),
    (Optional[Path], "x/y", Path("x/y")),  # noqa: UP045
    (Literal["nearest", "bilinear"], "bilinear", "bilinear"),
    (Literal[1, 2], "2", 2),
])
def test_coerce(kind, text, expected):
    value = coerce(text, _p(kind), "m")
    assert value == expected and type(value) is type(expected)


def test_coerce_path_expands_user():
    assert coerce("~/x", _p(Path)) == Path.home() / "x"


def test_coerce_untyped_follows_the_default():
    assert coerce("3", _p(inspect.Parameter.empty, 1.5)) == 3.0
    assert coerce("3", _p(inspect.Parameter.empty, 2)) == 3
    assert coerce("3", _p(inspect.Parameter.empty)) == "3"


@pytest.mark.parametrize("kind, text, fragment", [
    (bool, "maybe", "m:x: expected bool, got 'maybe'"),
    (int, "1.5", "m:x: expected int, got '1.5'"),
    (int, "", "m:x: expected int, got ''"),
    (float, "fast", "m:x: expected float, got 'fast'"),
    (Optional[int], "x", "m:x: expected int, got 'x'"),  # noqa: UP045
    (Literal["a", "b"], "c", "m:x: expected one of 'a', 'b', got 'c'"),
])
def test_coerce_errors(kind, text, fragment):
    with pytest.raises(SpecError, match=fragment.replace("(", r"\(")):
        coerce(text, _p(kind), "m")


# --------------------------------------------------------------------------- create


class Toy(Method):
    """A toy method for the registry tests.

    scale: multiplies the ground truth
    steps: number of steps
    flag: a switch
    where: an optional folder
    mode: how to do it
    """

    def __init__(self, scale: float = 1.0, steps: int = 3, flag: bool = False, where: Path | None = None,
                 mode: Literal["a", "b"] = "a") -> None:
        if steps < 1:
            raise ValueError("steps must be >= 1")
        super().__init__()
        self.scale, self.steps, self.flag, self.where, self.mode = scale, steps, flag, where, mode

    def predict(self, lf):
        return Prediction(disparity=lf.gt_disparity() * self.scale)


class NeedsPath(Method):
    """Needs a path.

    path: required folder
    """

    def __init__(self, path: Path) -> None:
        super().__init__(path=path)


@pytest.fixture()
def reg() -> MethodRegistry:
    r = MethodRegistry(group=None)  # no entry points: only what the test registers
    register_method("toy", registry=r)(Toy)
    register_method("needs-path", registry=r)(NeedsPath)
    return r


def test_create_with_keyword_parameters(reg):
    m = reg.create("toy", scale=2.0, flag=True)
    assert isinstance(m, Toy) and (m.scale, m.steps, m.flag, m.mode) == (2.0, 3, True, "a")
    assert m.name == "toy" and m.params == {"scale": 2.0, "flag": True}
    assert m.label == "toy:scale=2.0,flag=True"
    lf = ArrayLightField(np.zeros((9, 9, 4, 4), np.float32), gt=np.ones((4, 4), np.float32))
    pred = m.run(lf)
    assert np.array_equal(pred.disparity, np.full((4, 4), 2.0, np.float32)) and pred.runtime_s >= 0


def test_create_from_spec_converts_types(reg):
    m = reg.create_from_spec("toy:scale=0.5,steps=4,flag=yes,where=~/runs,mode=b")
    assert (m.scale, m.steps, m.flag, m.where, m.mode) == (0.5, 4, True, Path.home() / "runs", "b")
    assert type(m.steps) is int and type(m.scale) is float
    assert reg.create_from_spec("toy:where=none").where is None


@pytest.mark.parametrize("spec, fragment", [
    ("nope", "Unknown method 'nope'. Available: needs-path, toy"),
    ("toy:speed=3", "method 'toy' has no parameter 'speed'; parameters: scale, steps, flag, where, mode"),
    ("toy:steps=two", "toy:steps: expected int, got 'two'"),
    ("toy:mode=c", "toy:mode: expected one of 'a', 'b', got 'c'"),
    ("toy:steps=0", "method 'toy': steps must be >= 1"),
    ("needs-path", "method 'needs-path' needs parameter path (e.g. needs-path:path=...)"),
])
def test_spec_errors(reg, spec, fragment):
    with pytest.raises(SpecError) as info:
        reg.create_from_spec(spec)
    assert fragment in str(info.value) and "\n" not in str(info.value)


def test_unknown_method_lists_the_available_ones(reg):
    with pytest.raises(SpecError, match="Available: needs-path, toy"):
        reg.create("nope")
    with pytest.raises(SpecError, match="has no parameter 'speed'"):
        reg.create("toy", speed=1)


def test_registering_two_factories_under_one_name_fails(reg):
    register_method("toy", registry=reg)(Toy)  # the same factory again is fine

    class Other(Toy):
        pass

    with pytest.raises(ValueError, match="already registered"):
        register_method("toy", registry=reg)(Other)


def test_describe_lists_parameters_with_types_defaults_and_help(reg):
    text = reg.info("toy").describe()
    assert text.splitlines()[0] == "toy: A toy method for the registry tests."
    assert "scale (float, default 1.0): multiplies the ground truth" in text
    assert "steps (int, default 3): number of steps" in text
    assert "mode (one of 'a', 'b', default 'a'): how to do it" in text
    assert "path (path, required): required folder" in reg.info("needs-path").describe()


def test_builtin_methods_through_the_global_registry(tmp_path):
    assert {"gt", "published"} <= set(registry.REGISTRY.names())
    gt = np.random.default_rng(0).uniform(-1, 1, (16, 16)).astype(np.float32)
    scene = HCIScene(write_scene(tmp_path, "s", size=16, views=False, gt=gt))
    assert np.array_equal(registry.create("gt").run(scene).disparity, gt)
    with pytest.raises(SpecError, match="needs parameter path"):
        registry.create("published")
    with pytest.raises(SpecError, match="not a submission folder"):
        registry.create_from_spec(f"published:path={tmp_path}")


# --------------------------------------------------------------------------- plugins


@pytest.fixture()
def plugin(tmp_path, monkeypatch):
    names = install_fake_plugin(tmp_path / "site", monkeypatch)
    yield names
    forget_module(names["module"])


def test_the_registry_discovers_a_third_party_plugin(plugin, tmp_path):
    reg = registry.REGISTRY
    names = reg.names()
    assert plugin["centre"] in names and plugin["offset"] in names
    assert {"gt", "published"} <= set(names)  # the built-ins come through the same entry-point group
    assert plugin["broken"] in reg.load_errors and "ModuleNotFoundError" in reg.load_errors[plugin["broken"]]
    with pytest.raises(SpecError, match="plugin failed to load"):
        reg.info(plugin["broken"])

    # module entry point: the decorated class, with its parameter documented the deprecated way (a
    # `name: text` line of the class docstring), which keeps working for plugins written before Annotated
    info = reg.info(plugin["centre"])
    assert info.source == plugin["module"]
    assert "gain (float, default 1.0): factor applied to the centre view" in info.describe()
    lf = ArrayLightField(np.arange(81 * 4, dtype=np.float32).reshape(9, 9, 2, 2))
    pred = reg.create_from_spec(f"{plugin['centre']}:gain=2").run(lf)
    assert np.array_equal(pred.disparity, 2 * lf.views[4, 4])

    # factory entry point: registered under the entry point's name
    gt = np.ones((2, 2), np.float32)
    m = reg.create(plugin["offset"], offset=0.5)
    assert m.label == f"{plugin['offset']}:offset=0.5"
    assert np.array_equal(m.run(ArrayLightField(lf.views, gt=gt)).disparity, gt + 0.5)


def test_the_global_helpers_see_plugins(plugin):
    assert plugin["centre"] in [i.name for i in registry.list_methods()]
    assert registry.REGISTRY.info(plugin["offset"]).params["offset"].default == 0.0
    assert registry.create(plugin["centre"]).gain == 1.0


# --------------------------------------------------------------------------- the Method contract


def test_every_hook_is_declared_on_the_base_class_with_a_default():
    from lfbench.method.base import HOOKS, overrides

    lf = ArrayLightField(np.zeros((9, 9, 4, 4), np.float32))
    m = Method()
    assert HOOKS == ("predict", "available_for", "describe_variant", "offline_variants", "to")
    assert all(getattr(Method, h).__doc__ for h in HOOKS)
    assert m.available_for(lf) is None and m.describe_variant() == {} and m.offline_variants() == []
    assert m.to("cuda") is m
    with pytest.raises(NotImplementedError, match="Method does not implement predict"):
        m.predict(lf)
    assert overrides(Toy, "predict") and not overrides(Toy, "describe_variant")


def test_create_refuses_what_is_not_a_method(reg):
    def returns_a_dict(scale: float = 1.0):
        """Not a method."""
        return {"scale": scale}

    register_method("dict", registry=reg)(returns_a_dict)
    with pytest.raises(SpecError, match="method 'dict': .*returns_a_dict returned a dict, which is not a Method"):
        reg.create("dict")

    class NotAMethod:
        """A plain class."""

    with pytest.raises(TypeError, match="NotAMethod registered as method 'plain' is not a Method"):
        register_method("plain", registry=reg)(NotAMethod)


def test_name_and_params_are_set_once_by_the_registry(reg):
    m = reg.create("toy", steps=4)
    assert (m.name, m.params) == ("toy", {"steps": 4})
    m.params["steps"] = 9  # a copy: the method keeps its own
    assert m.params == {"steps": 4} and m.label == "toy:steps=4"
    with pytest.raises(AttributeError):
        m.name = "other"
    with pytest.raises(RuntimeError, match="set once"):
        m._bind("other", {})
    assert Toy().name == "" and Toy().params == {}  # made without the registry


def test_a_variant_is_the_factory_registered_with_its_defaults(reg):
    register_method("toy-fast", registry=reg, defaults={"steps": 1, "mode": "b"},
                    doc="The toy in one step.\n\nsteps: one step only")(Toy)
    info = reg.info("toy-fast")
    assert info.factory is Toy and info.summary == "The toy in one step."
    assert (info.params["steps"].default, info.params["mode"].default, info.params["scale"].default) == (1, "b", 1.0)
    assert info.params["steps"].help == "one step only" and info.params["scale"].help == "multiplies the ground truth"
    m = reg.create("toy-fast", scale=2.0)
    assert (m.steps, m.mode, m.scale) == (1, "b", 2.0)
    assert m.label == "toy-fast:scale=2.0"  # the variant's defaults are not spelled out
    assert reg.create("toy-fast", steps=5).steps == 5
    text = info.describe()
    assert "steps (int, default 1): one step only" in text and "mode (one of 'a', 'b', default 'b')" in text
    assert reg.info("toy").params["steps"].default == 3  # the base name keeps its own defaults
    with pytest.raises(TypeError, match="variant 'bad' gives defaults for speed"):
        register_method("bad", registry=reg, defaults={"speed": 2})(Toy)
    with pytest.raises(TypeError, match="variant 'bad' gives help for speed"):
        register_method("bad", registry=reg, help={"speed": "how fast"})(Toy)
    register_method("toy-b", registry=reg, defaults={"mode": "b"}, doc="The toy, mode b.", help={"mode": "b only"})(Toy)
    assert reg.info("toy-b").params["mode"].help == "b only" and reg.info("toy-b").summary == "The toy, mode b."


def test_lfattnet_is_a_registered_variant_of_subfocal():
    sub, lfa = registry.REGISTRY.info("subfocal"), registry.REGISTRY.info("lfattnet")
    assert lfa.factory is sub.factory and lfa.defaults == {"interval": 1.0} and sub.defaults == {}
    assert lfa.params["interval"].default == 1.0 and sub.params["interval"].default == 0.5
    assert list(lfa.params) == list(sub.params)
    assert lfa.summary.startswith("LFattNet (Tsai et al., AAAI 2020)")
    assert lfa.params["interval"].help == "disparity step of the cost volume in px (LFattNet 1)"
    assert lfa.params["tile"].help == sub.params["tile"].help != ""
    m = registry.create("lfattnet")
    assert m.values["interval"] == 1.0 and m.label == "lfattnet" and m.variant == "lfattnet"
    assert m.shipped_weights.name == "lfattnet_small.pt"
