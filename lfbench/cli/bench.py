"""Speed and memory benchmarks (not part of the tests): inference per network parameter and precision,
training steps, the metric engine, and what a network contributes of its own (SubFocal: the cost volume
alone and the conv3d peak the others are judged against). ``--model NAME[:key=value,...]`` times any
registered trainable network (default ``subfocal``).

The network's own parameters are flags of ``inference``, ``train`` and ``suite``, each taking one or
more values to time (``--interval 1 0.5`` for SubFocal, ``--channels 4 8`` for a plugin's network;
``lfbench bench inference --model NAME --help`` lists them), and so are the options a network adds to
the training bench (SubFocal: ``--path``, ``--weight-grad``). The network is checked before any case
runs: bad parameters or weights of another network are one error line (exit 2).

Every case runs in a fresh Python process; peak_memory_gb is that process's peak RSS. Records (JSON
list) carry the machine (CPU, cores, torch threads and version, load average). Without a subcommand
``lfbench bench`` runs ``suite``: the conv peak, one 512x512 scene at interval 0.5 in fp32 and bf16,
the volume, training and metric benches. On a loaded 2-core CPU that takes about 30 min; the whole
grid (``lfbench bench suite --interval 1 0.5 0.25 0.1``) about 3 h; ``--quick`` (64x64) under a minute.

Examples:
  lfbench bench inference --size 512 --interval 0.5 --precision bf16 --json OUT.json
  lfbench bench inference --interval 1 0.5 0.25 0.1 --precision fp32 bf16 --json grid.json
  lfbench bench volume --size 512 --method gather grid_sample
  lfbench bench train --width 150 16 --batch 2
  lfbench bench train --width 16 --batch 4 --path reference fast --rounds 2   # the training speed-up
  lfbench bench suite --quick --json quick.json
  lfbench bench suite --out benchmarks/results   # kept as benchmarks/results/<date>-<host>.json and .md
  lfbench bench inference --device cuda --interval 0.5 0.1 --precision fp32 bf16
  lfbench bench inference --model tinycnn:layers=3 --channels 4 8 --size 128   # a plugin's network
  lfbench bench inference --size 256 --repeat 50 --mean --precision fp32 --interval 0.1 --d-min -0.5 \\
      --d-max 1.6 --no-peak --json table3_runtime.json   # the runtime column of SubFocal's Table III
  lfbench bench inference --model subfocal:interval=0.1,d_min=-0.5,d_max=1.6 lfattnet:d_min=-1,d_max=2 \\
      --size 256 --repeat 50 --mean --precision fp32 --no-peak   # several networks, each with its ratio to SubFocal

``inference --model A B ...`` (or --model repeated) times several networks one after the other at the same input,
each with the parameters of its spec (their own flags are not offered then); every row gets ratio_to_reference,
its time over that of --ratio-to's network (default subfocal when timed, else the first) at the same size and
precision.

--device (auto, cpu, cuda, cuda:K; default auto) places the peak, inference and training cases: on CUDA
the clocks are read after torch.cuda.synchronize, peak_memory_gb is torch.cuda.max_memory_allocated and
fp32 is IEEE fp32 (TF32 off). A bf16 case on a CPU without bf16 instructions is recorded as skipped
(with the reason) and does not change the exit code.

Each inference case sits between conv3d peaks of both precisions (unless --no-peak), so its row gives the
ratio to the fp32 floor and to the bf16 floor (network FLOPs / peak) side by side; on a CPU without bf16
instructions the bf16 peak is one skipped line and the bf16 ratio reads "skipped".
"""

from __future__ import annotations

import argparse
import itertools
from dataclasses import dataclass
from pathlib import Path

from lfbench.cli.argtypes import add_flag, flag_type
from lfbench.method.trainable import DEFAULT_TRAINABLE, bench_options
from lfbench.utils.flags import DEVICE, MAX_MEMORY, REPEAT, SCENE_COUNT, THREADS, TIMEOUT, flag_name, section_flags
from lfbench.utils.options import option

HELP = "speed and memory benchmarks (inference, cost volume, training, metrics, conv peak)"

# Bounds of the flags, checked when they are parsed (one usage line, exit 2) before any case runs: a case
# allocates from them (81 views of SIZE^2 px, BATCH patches of PATCH^2 px), in a worker process.
MAX_SIZE = 4096  # px per side of a timed light field (as lfbench synth)
MAX_BATCH = 4096  # as a training config's batch_size
MAX_PATCH = 1024  # px, as a training config's patch
MAX_COUNT = 10**6  # steps, repeats, rounds, scenes, methods


@dataclass(frozen=True, kw_only=True)
class BenchFlags:
    """The flags of the benches (each bench adds those it uses), declared once."""

    size: int = option(512, help="image size in px (a size x size scene, 81 views)", low=8, high=MAX_SIZE, metavar="S")
    tile: int = option(0, help="core tile size in px (0 = the network's choice: SubFocal's from --max-memory)",
                       low=0, high=MAX_SIZE, metavar="PX")
    batch: int = option(2, help="patches per training step", low=1, high=MAX_BATCH, metavar="N")
    train_batch: int = option(2, help="patches per step of the training cases", low=1, high=MAX_BATCH, metavar="N")
    patch: int = option(32, help="patch size in px", low=8, high=MAX_PATCH, metavar="PX")
    steps: int = option(2, help="timed training steps", low=1, high=MAX_COUNT, metavar="N")
    train_steps: int = option(2, help="timed steps of the training cases", low=1, high=MAX_COUNT, metavar="N")
    warmup: int = option(1, help="untimed steps first (one-time costs: kernel setup, caches, the heap growing to "
                         "its size)", low=0, high=MAX_COUNT, metavar="N")
    rounds: int = option(1, help="run the cases this many times, interleaved (before/after under the same load)",
                         low=1, high=MAX_COUNT, metavar="N")
    methods: int = option(5, help="methods scored on each scene", low=1, high=1000, metavar="N")
    interval: float = option(0.5, help="disparity step of the cost volume in px", low=0, high=1e12, low_open=True,
                             metavar="PX")


_BENCH = section_flags(BenchFlags)
SIZE, TILE, BATCH, TRAIN_BATCH, PATCH, STEPS, TRAIN_STEPS, WARMUP, ROUNDS, METHODS, INTERVAL = (
    _BENCH[name] for name in ("size", "tile", "batch", "train_batch", "patch", "steps", "train_steps", "warmup",
                              "rounds", "methods", "interval"))
_NETWORK_BENCHES = ("inference", "train", "suite")  # the benches whose parsers take the network's own flags


class _NetworkParser(argparse.ArgumentParser):
    """A bench's parser: before parsing, it adds the flags of the network ``--model`` names (its parameters,
    and for the training bench its options), so that ``--help`` lists them and they parse with its types."""

    def error(self, message: str):  # type: ignore[override]
        self.exit(2, f"{self.prog}: error: {message} (see {self.prog} --help)\n")

    def parse_known_args(self, args=None, namespace=None):  # type: ignore[override]
        if getattr(self, "_bench", None) in _NETWORK_BENCHES and not getattr(self, "_network_flags", False):
            self._network_flags = True
            from lfbench.utils.errors import LFBenchError

            models = _models_in(list(args or []))
            try:
                if len(models) == 1:  # several networks: each one's parameters are in its --model spec
                    _add_network_flags(self, self._bench, models[0])
            except LFBenchError as exc:
                self.error(f"--model: {exc}")
        return super().parse_known_args(args, namespace)


def _models_in(args: list[str]) -> list[str]:
    """The values of every ``--model`` in ``args`` (``--model A B``, ``--model A --model B``; the default
    network when absent)."""
    found: list[str] = []
    for i, arg in enumerate(args):
        if arg == "--model":
            found += itertools.takewhile(lambda a: not a.startswith("-"), args[i + 1:])
        elif arg.startswith("--model="):
            found.append(arg.split("=", 1)[1])
    return found or [DEFAULT_TRAINABLE]


def _add_network_flags(p: argparse.ArgumentParser, bench: str, model: str) -> None:
    """``--PARAM V [V ...]`` for every parameter of the network (one case per value; a parameter whose flag
    the bench has already is set through ``--model NAME:key=value``) and, for the training bench, the
    options the network adds (:attr:`Trainable.train_bench_options`)."""
    from lfbench.method.params import parse_spec
    from lfbench.method.trainable import get_trainable

    name, _ = parse_spec(model)
    trainable = get_trainable(name)
    taken = {s for action in p._actions for s in action.option_strings}
    group = p.add_argument_group(f"parameters of the network {name!r} (several values: one case each)")
    for key, param in trainable.parameters().items():
        flag = flag_name(key)
        if flag in taken:
            continue

        timed = trainable.train_bench_defaults.get(key) if bench in ("train", "suite") else None
        default = " ".join(map(str, timed)) + " (training)" if timed else repr(param.default)
        group.add_argument(flag, dest=f"net_{key}", nargs="+", type=flag_type(param), metavar=key.upper(),
                           help=f"{param.help or key} (default: {default})")
    if bench == "train":
        for option in bench_options(trainable.train_bench_options):
            if option.flag not in taken:
                add_flag(group, option, default=None, nargs="+", dest=f"opt_{option.name}")


def _common(p: argparse.ArgumentParser, several: bool = False) -> None:
    """The flags of every bench; ``several``: ``--model`` takes several networks (the inference bench)."""
    p.add_argument("--json", type=Path, metavar="OUT.json", help="write the records (a JSON list) here")
    p.add_argument("--table", type=Path, metavar="OUT.md", help="also write the table (Markdown) here")
    add_flag(p, THREADS)
    add_flag(p, TIMEOUT)
    if not several:
        p.add_argument("--model", default=DEFAULT_TRAINABLE, metavar="NAME[:key=value,...]",
                       help=f"trainable network to time, with parameters (default {DEFAULT_TRAINABLE}; see lfbench "
                            "methods)")
        return
    p.add_argument("--model", nargs="+", action="extend", default=None, metavar="NAME[:key=value,...]",
                   help=f"trainable network(s) to time, with parameters (default {DEFAULT_TRAINABLE}; see lfbench "
                        "methods). Several (--model A B or --model A --model B) are timed one after the other on "
                        "the same input, each with the parameters of its spec (their own flags are then not "
                        "offered), and each row gets its time's ratio to --ratio-to's")
    p.add_argument("--ratio-to", metavar="NAME[:key=value,...]",
                   help=f"the network whose time the others are divided by: one of the --model values, or the name "
                        f"of one (its first) (default: {DEFAULT_TRAINABLE} when timed, else the first --model; "
                        "only with several networks unless given)")


def _device_option(p: argparse.ArgumentParser) -> None:
    add_flag(p, DEVICE, default="auto", detail="the peak, inference and training cases")


def _inference_options(p: argparse.ArgumentParser, size: int) -> None:
    add_flag(p, SIZE, default=size)
    p.add_argument("--precision", nargs="+", default=["fp32", "bf16"], choices=["fp32", "bf16"])
    p.add_argument("--weights", help="weights file of the network (default: random weights)")
    add_flag(p, MAX_MEMORY)
    add_flag(p, TILE)
    add_flag(p, REPEAT, detail="the best is kept, or their mean: --mean")
    p.add_argument("--mean", action="store_true",
                   help="seconds = the mean of the --repeat runs after one warm-up run, not the best (as papers "
                        "report runtime: SubFocal's Table III is --size 256 --repeat 50 --mean)")
    p.add_argument("--no-peak", action="store_true", help="do not measure the conv3d peak around each case")
    _device_option(p)


def _bench_parser(sub, name: str, **kwargs) -> argparse.ArgumentParser:
    p = sub.add_parser(name, formatter_class=argparse.RawDescriptionHelpFormatter, **kwargs)
    p._bench = name
    return p


def add_arguments(p: argparse.ArgumentParser) -> None:
    sub = p.add_subparsers(dest="which", metavar="BENCH", parser_class=_NetworkParser)
    s = _bench_parser(sub, "suite", help="all benches (default)", description="All benches; see lfbench bench --help.")
    _inference_options(s, 512)
    s.add_argument("--quick", action="store_true", help="64x64 scene, tiny training and metric cases (seconds)")
    s.add_argument("--skip", nargs="+", default=[], choices=["peak", "inference", "volume", "train", "metrics"])
    s.add_argument("--out", type=Path, metavar="DIR",
                   help="keep the run: the records and the table in DIR as <date>-<host>[-quick].json and .md, so "
                        "that runs on several machines sit side by side (--json / --table name a file instead)")
    add_flag(s, TRAIN_BATCH)
    add_flag(s, TRAIN_STEPS)
    _common(s)
    i = _bench_parser(sub, "inference", help="one scene per network parameter x precision (seconds, peak memory, "
                                             "GFLOP/s)")
    _inference_options(i, 512)
    _common(i, several=True)
    v = _bench_parser(sub, "volume", help="the cost volume alone (GB/s; SubFocal's own bench)")
    add_flag(v, SIZE)
    add_flag(v, INTERVAL, nargs="+", default=[0.5])
    v.add_argument("--precision", nargs="+", default=["fp32", "bf16"], choices=["fp32", "bf16"])
    v.add_argument("--method", nargs="+", default=["gather", "grid_sample"], choices=["gather", "grid_sample"])
    add_flag(v, REPEAT)
    _common(v)
    t = _bench_parser(sub, "train", help="training steps per second (Adam + L1 on random patches)")
    add_flag(t, BATCH)
    add_flag(t, PATCH)
    add_flag(t, STEPS)
    add_flag(t, WARMUP)
    t.add_argument("--no-channels-last", action="store_true")
    t.add_argument("--precision", nargs="+", default=["fp32"], choices=["fp32", "bf16"],
                   help="fp32 and/or bf16 (autocast of the forward pass, as [training] precision = 'bf16')")
    add_flag(t, ROUNDS)
    _device_option(t)
    _common(t)
    m = _bench_parser(sub, "metrics", help="the metric engine over synthetic scenes x methods")
    add_flag(m, SCENE_COUNT, default=12)
    add_flag(m, METHODS)
    add_flag(m, SIZE)
    add_flag(m, REPEAT)
    _common(m)
    k = _bench_parser(sub, "peak", help="the conv3d peak (GFLOP/s) of the paper's 3D convolution (SubFocal's own "
                                        "bench)")
    k.add_argument("--precision", nargs="+", default=["fp32", "bf16"], choices=["fp32", "bf16"])
    add_flag(k, REPEAT, default=3)
    _device_option(k)
    _common(k)


def _model(args: argparse.Namespace) -> tuple[str, dict, object]:
    """(network name, its parameters from --model, the trainable); SpecError for an unknown one."""
    from lfbench.method.params import coerce_params, parse_spec
    from lfbench.method.trainable import get_trainable

    spec = args.model if isinstance(args.model, str) else (args.model or [DEFAULT_TRAINABLE])[0]
    name, raw = parse_spec(spec)
    trainable = get_trainable(name)
    return name, coerce_params(raw, trainable.parameters(), name, "network"), trainable


def _sweep(args: argparse.Namespace, trainable, base: dict, defaults: dict | None = None) -> list[dict]:
    """The network parameters of each case: ``base`` (from --model) with every combination of the values given
    to the network's flags (or ``defaults``, e.g. SubFocal's training widths, for flags not given)."""
    values = {}
    for key in trainable.parameters():
        given = getattr(args, f"net_{key}", None)
        if given is None and defaults and key in defaults and key not in base:
            given = list(defaults[key])
        if given is not None:
            values[key] = given
    return [{**base, **dict(zip(values, combo, strict=True))} for combo in itertools.product(*values.values())]


class _FloorPeaks:
    """The peak cases measured around each inference case: one per precision asked for (``--precision``), so
    that every inference record gets its ratio to the floor of each of them (fp32 and bf16 when both are
    asked). A peak this machine cannot run (bf16 on a CPU without bf16 convolutions) is listed once, as its
    one skipped record, not around every case; a precision not asked for is never measured."""

    def __init__(self, model: str, th: dict, precisions: list[str]) -> None:
        from lfbench.runs.bench import skip_reason

        self.params = [{"model": model, "precision": p, **th} for p in dict.fromkeys(precisions)]
        self.skipped = [skip_reason("peak", params) is not None for params in self.params]
        self.listed: set[int] = set()

    def cases(self) -> list[tuple[str, dict]]:
        out = []
        for i, params in enumerate(self.params):
            if self.skipped[i] and i in self.listed:
                continue
            self.listed.add(i)
            out.append(("peak", dict(params)))
        return out


def _cases(args: argparse.Namespace) -> list[tuple[str, dict]]:
    """(bench, params) in the order they run."""
    which = args.which
    th = {"threads": args.threads}
    cpu = dict(th)  # the volume bench runs on the CPU
    if getattr(args, "device", None) is not None:  # cases that run on a device (resolved by run())
        th["device"] = args.device
    model, model_params, trainable = _model(args)
    has = trainable.benches  # the network's own benches (SubFocal: peak, volume)
    cases: list[tuple[str, dict]] = []
    if which in ("inference", "suite"):
        skip = set(getattr(args, "skip", []))
        size = 64 if getattr(args, "quick", False) else args.size
        if which == "inference" or "inference" not in skip:
            peaks = "peak" in has and not args.no_peak and not (which == "suite" and "peak" in skip)
            floors = _FloorPeaks(model, th, args.precision)
            for net in _sweep(args, trainable, model_params):
                for precision in args.precision:
                    if peaks:
                        cases += floors.cases()
                    cases.append(("inference", {"model": model, **net, "size": size, "precision": precision,
                                                "weights": args.weights, "max_memory_gb": args.max_memory,
                                                "tile": args.tile, "repeat": args.repeat,
                                                "statistic": "mean" if args.mean else "best", **th}))
            if peaks:  # the peaks again after the last case: each case sits between two peak measurements
                cases += floors.cases()
        elif "peak" not in skip and "peak" in has:  # the suite without inference: peaks beside the training bench
            cases += [("peak", {"model": model, "precision": p, **th}) for p in args.precision]
        if which == "suite":
            quick = args.quick
            if "volume" not in skip and "volume" in has:
                cases += [("volume", {"model": model, "size": size, "interval": 0.5, "precision": p,
                                      "method": "gather", **cpu}) for p in args.precision]
                cases.append(("volume", {"model": model, "size": size, "interval": 0.5, "precision": "fp32",
                                         "method": "grid_sample", **cpu}))
            if "train" not in skip:
                for net in _sweep(args, trainable, model_params, trainable.train_bench_defaults):
                    cases.append(("train", {"model": model, **net, "batch": 1 if quick else args.train_batch,
                                            "patch": 16 if quick else 32, "steps": 1 if quick else args.train_steps,
                                            **th}))
            if "metrics" not in skip:
                cases.append(("metrics", {"scenes": 12, "methods": 5, "size": 128 if quick else 512}))
    elif which == "volume":
        for interval in args.interval:
            for method in args.method:
                for precision in (args.precision if method == "gather" else ["fp32"]):
                    cases.append(("volume", {"model": model, "size": args.size, "interval": interval,
                                             "precision": precision, "method": method, "repeat": args.repeat, **th}))
    elif which == "train":
        chosen = {o.name: getattr(args, f"opt_{o.name}", None) for o in bench_options(trainable.train_bench_options)}
        variants = trainable.train_variants(chosen)
        nets = _sweep(args, trainable, model_params, trainable.train_bench_defaults)
        cases = [("train", {"model": model, **net, "batch": args.batch, "patch": args.patch, "steps": args.steps,
                            "warmup": args.warmup, "channels_last": not args.no_channels_last, **variant,
                            "precision": precision, **th})
                 for _ in range(max(1, args.rounds)) for net in nets for variant in variants
                 for precision in args.precision]
    elif which == "metrics":
        cases = [("metrics", {"scenes": args.scenes, "methods": args.methods, "size": args.size,
                              "repeat": args.repeat})]
    elif which == "peak":
        cases = [("peak", {"model": model, "precision": p, "repeat": args.repeat, **th}) for p in args.precision]
    return cases


def _check_networks(args: argparse.Namespace, cases: list[tuple[str, dict]]) -> None:
    """SpecError (or the DataError of the weights file) naming --model, before any case runs, when a case
    would build a network its trainable refuses: unknown or ill-typed parameters, values out of bounds, more
    than MAX_NETWORK_BYTES of parameters (checked on the meta device), weights of another network or that do
    not fit; and, for a network that has no check of its own, when it fails one forward pass on a small
    light field (lfbench.method.trainable.Trainable.check_forward)."""
    from lfbench.method.trainable import Trainable, construct
    from lfbench.utils.errors import SpecError

    _, _, trainable = _model(args)
    accepted = trainable.parameters()
    trusted = type(trainable).check is not Trainable.check  # a network that checks its parameters itself
    checked: list[tuple[dict, str | None]] = []
    for bench, params in cases:
        net = {k: v for k, v in params.items() if k in accepted}
        weights = params.get("weights") if bench == "inference" else None
        if bench not in ("inference", "train") or (net, weights) in checked:
            continue
        checked.append((net, weights))
        try:
            trainable.check_params(net)
            built = trainable.load(Path(weights), **net) if weights else None  # DataError: not its weights
            if not trusted:
                trainable.check_forward(built if built is not None else construct(trainable.build, net))
        except (TypeError, ValueError) as exc:
            raise SpecError(f"--model {args.model}: {' '.join(str(exc).split())[:240]}") from None


def _line(record: dict) -> str:
    from lfbench.runs.bench import format_value

    if "error" in record:
        return f"[{record.get('bench')}] error: {record['error']}"
    if "skipped" in record:
        return f"[{record.get('bench')}] {record.get('precision', '')} skipped: {record['skipped']}"
    network = list(record.get("network_params", []))
    keys = [k for k in ("model_spec", "size", *network, "precision", "method", "batch", *record.get("variant", []),
                        "seconds",
                        "peak_memory_gb", "gflops_per_s", "gb_per_s", "steps_per_s", "cpu_seconds", "scores_per_s")
            if k in record]
    load = (record.get("machine") or {}).get("load_average")
    return f"[{record['bench']}] " + ", ".join(f"{k} {format_value(record[k])}" for k in dict.fromkeys(keys)) + \
        f" (load {load})"


def _output(args: argparse.Namespace, records: list[dict]) -> list[dict]:
    """What the JSON file holds: every record, or for ``inference`` only the inference records (each carries
    its peak)."""
    return records if args.which != "inference" else [r for r in records if r.get("bench") == "inference"]


def _networks(args: argparse.Namespace) -> tuple[list[str], str | None]:
    """(the --model specs to time, one after the other; the spec whose time the others are divided by, None when
    one network is timed without --ratio-to). SpecError (exit 2) for a --ratio-to that is none of them."""
    from lfbench.method.params import parse_spec
    from lfbench.utils.errors import SpecError

    if not isinstance(args.model, list):  # the benches that time one network
        return [args.model], None
    models = list(dict.fromkeys(args.model or [DEFAULT_TRAINABLE]))
    names = [parse_spec(m)[0] for m in models]
    asked = getattr(args, "ratio_to", None)
    if asked is None:
        if len(models) == 1:
            return models, None
        asked = DEFAULT_TRAINABLE if DEFAULT_TRAINABLE in names else models[0]
    if asked in models:
        return models, asked
    if asked in names:
        return models, models[names.index(asked)]
    raise SpecError(f"--ratio-to {asked}: not one of the networks timed ({', '.join(models)})")


def _stamped_outputs(args: argparse.Namespace) -> None:
    """``suite --out DIR``: ``--json`` and ``--table``, where not given, as ``DIR/<YYYYmmdd-HHMM>-<host>[-quick]``
    ``.json`` and ``.md`` (named after the date and the machine, so that runs on several machines sit side by
    side)."""
    import platform
    import time

    stem = f"{time.strftime('%Y%m%d-%H%M')}-{platform.node() or 'host'}{'-quick' if args.quick else ''}"
    args.json = args.json or args.out / f"{stem}.json"
    args.table = args.table or args.out / f"{stem}.md"


def run(args: argparse.Namespace) -> int:
    from lfbench.runs.bench import attach_peaks, attach_ratios, run_isolated, table, write_json

    if args.which is None:  # the default: the suite with its defaults
        parser = argparse.ArgumentParser()
        add_arguments(parser)
        args = parser.parse_args(["suite"])
    if getattr(args, "device", None) is not None:
        from lfbench.utils.hardware import resolve_device

        args.device = str(resolve_device(args.device))  # SpecError (exit 2) before any case
    if getattr(args, "out", None) is not None:
        _stamped_outputs(args)
    from lfbench.utils.outputs import check_output_file

    for name in ("json", "table"):  # before any case (a link: the file it leads to)
        if getattr(args, name, None) is not None:
            setattr(args, name, check_output_file(getattr(args, name)))
    records: list[dict] = []
    models, reference = _networks(args)
    cases: list[tuple[str, dict]] = []
    specs: list[str | None] = []  # the --model spec of each case (None: a peak, no network's)
    for model in models:
        args.model = model
        mine = _cases(args)
        _check_networks(args, mine)
        cases += mine
        specs += [model if bench == "inference" else None for bench, _ in mine]
    print(f"lfbench bench {args.which}: {len(cases)} cases, each in a fresh process", flush=True)
    for (bench, params), spec in zip(cases, specs, strict=True):
        record = run_isolated(bench, params, args.timeout)
        if reference is not None and spec is not None:
            record["model_spec"] = spec
        records.append(record)
        print(_line(record), flush=True)
        if args.json:
            write_json(args.json, _output(args, records))
    records = attach_peaks(records)
    if reference is not None:
        records = attach_ratios(records, reference)
    if args.json:
        write_json(args.json, _output(args, records))
    text = table(records)
    print("\n" + text, end="")
    if args.table:
        from lfbench.utils.atomic import write_text

        write_text(args.table, text)
    return 1 if any("error" in r for r in records) else 0
