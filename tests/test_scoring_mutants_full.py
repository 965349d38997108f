"""The scoring core's mutants that the first full mutation run left alive because no selected test reached them:
the hostile-plugin guards (issue 39 items 2-3; their CLI tests, tests/test_hostile_round4.py, cannot run under
mutmut) and a few small functions. In lfbench/scoring/base.py: Metric.__call__'s guard of a plugin's function of
maps (the arguments it passes, the name its lines give, the checks of what it returns), _not_defined's message,
Metric.badness of a signed metric, MetricRegistry.register / add / _load_entry_point / register_family (the toolkit
id as an alias, the refusal of an id a family defines, a plugin's Metric under a taken id, the same object again);
in lfbench/scoring/pixelwise.py: _describe (how a plugin's sample function is named) and _sample_problem (each
problem of what it returns, in its words); in lfbench/scoring/metrics.py: primary_metric.

mutmut forks each mutant's child from a parent that imported lfbench and loaded the process-wide METRICS during
collection, so a test that relies on that registry never runs a mutated add or _load_entry_point: every registry
test here builds a fresh MetricRegistry in its body, of its own entry-point group, filled by a fake installed
distribution (tests/helpers.write_dist_info) or by register. The plugins' functions are given their module and
qualified name (``hostile_plugin``: tests/helpers.as_plugin) so that every error line is written out whole. Each
test names the class of mutants it kills. In-process, no subprocess, no CLI, fast. The survivors no input can tell
apart have their reasons in tools/mutation/classify.py.
"""

from __future__ import annotations

import sys
import uuid
from types import SimpleNamespace

import numpy as np
import pytest
from helpers import Anonymous, as_plugin, write_dist_info

from lfbench.scoring.base import Metric, MetricRegistry
from lfbench.scoring.metrics import primary_metric
from lfbench.scoring.pixels import PixelErrors
from lfbench.scoring.pixelwise import Mean, PixelMetric, Sample
from lfbench.utils.errors import LFBenchError, SpecError
from lfbench.utils.registry import NameTaken


def _raise(exc: BaseException):
    def fail(*args, **kwargs):
        raise exc
    return fail


def _metric(metric_id: str, fn=None, **kw) -> Metric:
    return Metric(id=metric_id, name=metric_id.title(), description="", unit="px",
                  fn=fn if fn is not None else as_plugin(lambda gt, pred, mask=None, *, toolkit=False: 0.0, "score"),
                  **kw)


# --------------------------------------------------------------------------- Metric.__call__: a plugin's function


GT, PRED, MASK = np.zeros((2, 2)), np.ones((2, 2)), np.ones((2, 2), bool)


def test_a_plugins_function_of_maps_gets_every_argument_as_given():
    """Mutants of the guarded call (`fn(gt, pred, mask, toolkit=toolkit, **context)`: an argument None or left
    out): the plugin gets the very arrays, toolkit and context; its number comes back as a float."""
    seen = []

    def score(gt, pred, mask=None, *, toolkit=False, **context):
        seen.append((gt, pred, mask, toolkit, context))
        return np.float32(2.5)

    metric = _metric("plug", as_plugin(score, "score"))
    value = metric(GT, PRED, MASK, toolkit=True, scene="S", resolution="lowres")
    assert value == 2.5 and type(value) is float
    [(gt, pred, mask, toolkit, context)] = seen
    assert gt is GT and pred is PRED and mask is MASK and toolkit is True
    assert context == {"scene": "S", "resolution": "lowres"}


def test_a_plugins_function_that_raises_is_one_line_naming_it():
    """Mutants of the plugin's name (`name = f"{self.id!r} ({module}.{qualname})"`: None, the attribute names, fn
    for None) and of `plugin_failure(name, exc)` (an argument None or left out)."""
    metric = _metric("plug", as_plugin(_raise(RuntimeError("boom\nsecond line")), "Scorer.score"))
    with pytest.raises(LFBenchError) as info:
        metric(GT, PRED)
    assert str(info.value) == "metric plugin 'plug' (hostile_plugin.Scorer.score) failed: RuntimeError: boom"


def test_a_plugins_lfbench_error_passes_unchanged():
    """The plugin's own LFBenchError is re-raised as it is (not wrapped)."""
    own = LFBenchError("the plugin's own line")
    with pytest.raises(LFBenchError) as info:
        _metric("plug", as_plugin(_raise(own), "score"))(GT, PRED)
    assert info.value is own


def test_a_plugin_object_without_module_or_qualname_is_scored_and_named_by_its_type():
    """Mutants of the defaults of the name (getattr(fn, '__module__', '?') and getattr(fn, '__qualname__',
    type(fn).__name__): None, 'XX?XX', type(None), left out so that getattr raises) and of the own-code test's
    getattr without a default: such an object is a plugin, scored, and named `?.Anonymous`."""
    assert _metric("anon", Anonymous(lambda gt, pred, mask=None, *, toolkit=False: 3))(GT, PRED) == 3.0
    with pytest.raises(LFBenchError) as info:
        _metric("anon", Anonymous(_raise(ZeroDivisionError("division by zero"))))(GT, PRED)
    assert str(info.value) == "metric plugin 'anon' (?.Anonymous) failed: ZeroDivisionError: division by zero"


@pytest.mark.parametrize(("returned", "kind"), [
    ("abc", "str"), ("1.5", "str"), (None, "NoneType"), (True, "bool"), (np.bool_(False), "bool"),
    (np.array([1.0, 2.0]), "ndarray"), (1 + 2j, "complex"),
])
def test_a_plugins_function_that_returns_no_number_is_one_line_naming_it(returned, kind):
    """Mutants of the check of the value (`or` for `and`: a string that float() reads, '1.5', passed) and of its
    message (None, type(None))."""
    metric = _metric("plug", as_plugin(lambda *a, **k: returned, "score"))
    with pytest.raises(LFBenchError) as info:
        metric(GT, PRED)
    assert str(info.value) == f"metric plugin 'plug' (hostile_plugin.score) returned a {kind}, expected a number"


def test_an_undefined_metric_says_it_has_nothing_to_compute():
    """Mutant of _not_defined's message."""
    with pytest.raises(TypeError) as info:
        Metric.undefined("plugin_column")(GT, PRED)
    assert str(info.value) == "this metric id is not defined by lfbench: it has nothing to compute"


def test_a_signed_metrics_badness_is_its_magnitude():
    """Mutant of Metric.badness's `abs(value)` (abs(None))."""
    bias = _metric("bias", signed=True, value_range=(-10.0, 10.0))
    assert bias.badness(-2.5) == 2.5 and bias.badness(1.5) == 1.5 and bias.badness(0) == 0.0


# --------------------------------------------------------------------------- PixelMetric.draw: a plugin's sample


PX = PixelErrors.of_maps(np.zeros((2, 2)), np.ones((2, 2)))  # 4 pixels


def _draw(sample_fn):
    return PixelMetric(sample_fn, Mean(scale=1.0)).draw(PX)


def _drawn_problem(returned) -> str:
    with pytest.raises(LFBenchError) as info:
        _draw(as_plugin(lambda px, *, toolkit=False: returned, "sample"))
    prefix = "metric plugin hostile_plugin.sample returned "
    assert str(info.value).startswith(prefix)
    return str(info.value)[len(prefix):]


def test_a_plugins_sample_function_is_named_by_its_module_and_qualified_name():
    """Mutants of _describe's name (`getattr(fn, '__qualname__', None) or type(fn).__name__`: None, `and`, fn for
    None, the attribute's name) and of its module's attribute name: a function is `module.qualname`."""
    fn = as_plugin(_raise(RuntimeError("boom")), "Plugin.sample")
    with pytest.raises(LFBenchError) as info:
        _draw(fn)
    assert str(info.value) == "metric plugin hostile_plugin.Plugin.sample failed: RuntimeError: boom"


def test_a_plugins_sample_object_without_module_or_qualname_is_named_by_its_type():
    """Mutants of _describe's defaults (getattr(fn, '__module__', '?'): None, 'XX?XX', left out so that getattr
    raises; getattr(fn, '__qualname__', None) left out; type(None) for type(fn)): `?.Anonymous`."""
    with pytest.raises(LFBenchError) as info:
        _draw(Anonymous(_raise(RuntimeError("boom"))))
    assert str(info.value) == "metric plugin ?.Anonymous failed: RuntimeError: boom"
    with pytest.raises(LFBenchError) as info:
        _draw(Anonymous(lambda px, *, toolkit=False: "abc"))
    assert str(info.value) == "metric plugin ?.Anonymous returned a str, expected Sample(values, keep)"


@pytest.mark.parametrize(("returned", "problem"), [
    ("abc", "a str, expected Sample(values, keep)"),
    ([np.zeros(4), None], "a list, expected Sample(values, keep)"),  # two items, but no tuple
    ((np.zeros(4), None, None), "a tuple, expected Sample(values, keep)"),
])
def test_a_sample_that_is_no_pair_is_named_by_its_type(returned, problem):
    """Mutants of `not isinstance(sample, tuple) or len(sample) != 2` (`and`) and of the type's name
    (type(None))."""
    assert _drawn_problem(returned) == problem


@pytest.mark.parametrize(("values", "what"), [
    (np.zeros((2, 2)), "float64 (2, 2)"),
    ([0.0, 0.0, 0.0, 0.0], "list"),
    (np.array(["a", "b", "c", "d"]), "<U1 (4,)"),
    (np.zeros(4, complex), "complex128 (4,)"),
])
def test_sample_values_that_are_no_1d_array_of_numbers_are_described(values, what):
    """Mutants of the values' test (`and` for either `or`) and of their description (`what`: None, the
    ndarray test forced either way, type(None))."""
    assert _drawn_problem(Sample(values, None)) == f"values of {what}, expected a 1-D array of numbers"


def test_as_many_values_as_pixels_without_a_keep_mask():
    """Mutant of `None if values.size == n` (`or True`): 3 values for 4 pixels are refused, 4 are kept as they are."""
    assert _drawn_problem(Sample(np.zeros(3), None)) == "3 values for 4 pixels and no keep mask"
    values = np.arange(4.0)
    drawn = _draw(as_plugin(lambda px, *, toolkit=False: (values, None), "sample"))
    assert type(drawn) is Sample and drawn.values is values and drawn.keep is None


@pytest.mark.parametrize(("keep", "what"), [
    (np.ones(3, bool), "bool (3,)"),  # the right dtype, not one flag per pixel: 3 values, 3 kept
    (np.ones(4, np.int64), "int64 (4,)"),  # one per pixel, not bool
    ([True, True, True, True], "list"),
])
def test_a_keep_mask_that_is_not_bool_one_per_pixel_is_described(keep, what):
    """Mutants of the keep mask's test (`and` for either `or`) and of its description (`what`: None, the ndarray
    test forced either way, type(None))."""
    values = np.zeros(int(np.count_nonzero(keep)))
    assert _drawn_problem(Sample(values, keep)) == (
        f"a keep mask of {what}, expected bool (4,): one flag per scored pixel")


def test_as_many_values_as_kept_pixels():
    """Mutant of `None if kept_count == values.size` (`or True`): 3 values for 2 kept pixels are refused, 2 kept."""
    keep = np.array([True, False, True, False])
    assert _drawn_problem(Sample(np.zeros(3), keep)) == "3 values for 2 kept pixels"
    drawn = _draw(as_plugin(lambda px, *, toolkit=False: Sample(np.ones(2), keep), "sample"))
    assert drawn.keep is keep and drawn.values.tolist() == [1.0, 1.0]


# --------------------------------------------------------------------------- primary_metric


def test_the_primary_metric_is_the_first_badpix_in_table_order_else_the_first_metric():
    """Mutants of primary_metric: the test of a BadPix (`is None`, badpix_threshold(None)), the default when there
    is none (None, left out, ordered[1], the emptiness test forced either way)."""
    assert primary_metric(["mse_x100", "badpix_0.03", "badpix_0.07"]) == "badpix_0.07"
    assert primary_metric(["mse_x100", "badpix_0.2", "badpix_0.05"]) == "badpix_0.2"
    assert primary_metric(["q25_x100", "mse_x100"]) == "mse_x100"  # table order: MSE x100 before Q25
    assert primary_metric(["plugin_column"]) == "plugin_column"
    assert primary_metric([]) is None


# --------------------------------------------------------------------------- MetricRegistry


def test_register_names_an_object_that_is_no_metric_by_its_id():
    """Mutants of register's `getattr(metric, "id", "?")` (None, the attribute's name): the TypeError names the
    id the object claims."""
    with pytest.raises(TypeError) as info:
        MetricRegistry().register(SimpleNamespace(id="fake"))
    assert str(info.value) == "namespace(id='fake') registered as metric 'fake' is not a Metric"


def test_add_refuses_a_name_that_is_not_the_metrics_id():
    """Mutant of add's ValueError message (None)."""
    reg = MetricRegistry()
    with pytest.raises(ValueError) as info:
        reg.add("other", _metric("m"))
    assert str(info.value) == "metric 'm' registered as 'other': the name must be the metric's id"
    assert reg.registered() == []


def test_the_toolkit_id_is_an_alias_and_no_toolkit_id_adds_none():
    """Mutants of `aliases = aliases or ((obj.toolkit_id,) if obj.toolkit_id else ())` (`and`; the test forced
    either way: no alias, or the alias None) and of `super().add(name, ...)` (None): the families are asked about
    the id and the toolkit id, nothing else."""
    asked = []
    reg = MetricRegistry()
    reg.register_family("fam_<x>", lambda key: asked.append(key))
    with_tk, plain = _metric("m", toolkit_id="m_tk"), _metric("plain")
    assert reg.register(with_tk) is with_tk and reg.register(plain) is plain
    assert asked == ["m", "m_tk", "plain"]
    assert reg.registered() == ["m", "plain"]
    assert reg.get("m_tk") is with_tk and reg.get("m") is with_tk and reg.get("plain") is plain


def test_add_keeps_the_entry_and_aliases_given():
    """Mutants of `super().add(name, obj, entry=entry, aliases=aliases)` (entry None or left out, aliases left
    out) and of `aliases or ...` (`and`: the toolkit id instead of the aliases given)."""
    reg = MetricRegistry()
    reg.add("e", _metric("e", toolkit_id="e_tk"), entry="ENTRY", aliases=("e_alias",))
    assert reg.find("e") == "ENTRY" and reg.find("e_alias") == "ENTRY" and reg.find("e_tk") is None


def _family(key: str):
    return _metric(key) if key.startswith("fam_") else None


_family.__module__ = "plugin_families"


@pytest.mark.parametrize("make", [_family, Anonymous(_family)], ids=["module", "no-module"])
def test_an_id_a_family_defines_is_refused_naming_the_family(make):
    """Mutants of add's NameTaken (None) and of the family's module in it (getattr(make, '__module__', '?'): make
    or the attribute's name replaced or left out, the default None or 'XX?XX'), by the id and by the toolkit id;
    and register_family's append (None)."""
    where = "plugin_families" if make is _family else "?"
    reg = MetricRegistry()
    reg.register_family("fam_<x>", make)
    assert reg.family_patterns == ["fam_<x>"]
    for metric, key in ((_metric("fam_1"), "fam_1"), (_metric("ok", toolkit_id="fam_2"), "fam_2")):
        with pytest.raises(NameTaken) as info:
            reg.register(metric)
        assert str(info.value) == f"metric {key!r} is already defined by the family fam_<x> ({where})"
    assert reg.registered() == []
    assert reg.get("fam_3") == _metric("fam_3")


# --------------------------------------------------------------------------- MetricRegistry: plugins' entry points


_PLUGIN_MODULE = '''
from lfbench.scoring.base import Metric


def score(gt, pred, mask=None, *, toolkit=False):
    return 1.0


def _metric(metric_id, name="Plugin", **kw):
    return Metric(id=metric_id, name=name, description="", unit="px", fn=score, **kw)


NEW = _metric("plug_new", toolkit_id="plug_tk")
TAKEN = _metric("taken", name="Another")
SAME = _metric("same")
'''


@pytest.fixture()
def plugin(tmp_path, monkeypatch):
    """``install(entry_points)``: a fake installed distribution of a metrics group of its own (``[<group>]``
    lines ``entry_points``) whose module (returned with the group) holds NEW (id plug_new, toolkit id plug_tk),
    TAKEN (id taken) and SAME (id same)."""
    def install(entry_points: str) -> tuple[str, str]:
        tag = uuid.uuid4().hex[:10]
        module, group = f"metric_plugin_{tag}", f"lfbench_test_{tag}.metrics"
        site = tmp_path / "site"
        site.mkdir()
        (site / f"{module}.py").write_text(_PLUGIN_MODULE, encoding="utf-8")
        write_dist_info(site, f"metric-plugin-{tag}", f"[{group}]\n{entry_points.format(module=module)}\n")
        monkeypatch.syspath_prepend(str(site))
        monkeypatch.delitem(sys.modules, module, raising=False)
        return module, group
    return install


def test_a_plugins_metric_under_a_new_id_loads_with_its_toolkit_id(plugin):
    """Mutants of _load_entry_point that refuse every plugin or fail before its metric is registered
    (`super()._load_entry_point(None)`, `before is None and ...`, `before is not None`)."""
    module, group = plugin("plug_new = {module}:NEW")
    reg = MetricRegistry(group)
    assert reg.names() == ["plug_new"] and reg.load_errors == {}
    new = sys.modules[module].NEW
    assert reg.get("plug_tk") is new and reg.get("plug_new") is new


def test_a_plugins_metric_under_a_taken_id_is_refused_naming_both(plugin):
    """Mutants of the collision's detection in _load_entry_point (`before` None or looked up by None, the
    builtins test inverted, the plugin's object None, `self._same` without `not` or with an argument left out)
    and of its error (name_taken's entry point None or left out, the NameTaken None or its message's source)."""
    module, group = plugin("taken = {module}:TAKEN")
    reg = MetricRegistry(group)
    mine = reg.register(_metric("taken"))
    line = (f"metric plugin 'taken' ({module}:TAKEN) refused: metric 'taken' is already registered by "
            "lfbench.scoring.base")
    with pytest.raises(SpecError) as info:
        reg.names()
    assert str(info.value) == line
    with pytest.raises(SpecError) as later:
        reg.find("taken")  # every later lookup says it too
    assert str(later.value) == line
    assert reg.registered() == ["taken"] and reg._objects["taken"] is mine


def test_the_same_metric_again_under_its_entry_point_is_no_collision(plugin):
    """Mutants of `isinstance(obj, Metric) and not self._same(before, obj)` (`or`; _same of None and the object,
    or of ``before`` and None): the very object, registered before its entry point loads, is not refused; nor is
    a module entry point under a taken id."""
    module, group = plugin("same = {module}:SAME\ntaken = {module}")
    reg = MetricRegistry(group)
    __import__(module)
    same = reg.register(sys.modules[module].SAME)
    taken = reg.register(_metric("taken"))
    assert reg.names() == ["same", "taken"] and reg.load_errors == {}
    assert reg.get("same") is same and reg.get("taken") is taken


def test_all_loads_the_plugins_first(plugin):
    """Mutant of MetricRegistry.all's `if not self._loaded` (`if self._loaded`): a fresh registry's all() loads
    its group's plugins before listing (not an empty tuple), and lists them once loaded."""
    module, group = plugin("plug_new = {module}:NEW")
    reg = MetricRegistry(group)
    listed = reg.all()
    new = sys.modules[module].NEW
    assert listed == (new,) and reg.all() == (new,)


def test_find_loads_the_plugins_first(plugin):
    """Mutant of MetricRegistry.find's `if not self._loaded` (`if self._loaded`): the first lookup of a fresh
    registry loads all its group's plugins, in the group's order, whichever is asked for: the order of the metrics
    (tables, --metrics all) does not depend on what was looked up first."""
    module, group = plugin("plug_new = {module}:NEW\nsame = {module}:SAME")
    reg = MetricRegistry(group)
    found = reg.find("same")
    assert found is sys.modules[module].SAME and reg.registered() == ["plug_new", "same"]
    assert reg.find("plug_tk") is sys.modules[module].NEW and reg.names() == ["plug_new", "same"]
