"""The training loop behind ``lfbench train``: stages, validation, checkpoints, resume, DDP.

:func:`train` checks the config's network parameters and data first (nothing is generated or written for
a bad config), then :class:`Trainer` runs setup, resume, build, fit and export. Each stage gets a fresh
optimizer (and optional learning-rate schedule) from the network's ``Trainable.configure_optimizers``
(default: Adam with the stage's lr, betas, eps, at a constant rate).

Files under OUT:

- ``checkpoint.pt``: the last training checkpoint (atomic; model, optimizer, stage, step, RNG
  states, config). Re-running the same command resumes from it; a stage boundary is stored as
  (next stage, step 0, no optimizer), so the next stage starts with a fresh optimizer.
- ``stage<k>_<name>.pt``: the weights at the end of stage k; ``final.pt``: the weights at the
  end (inference format ``{"state_dict", "config": net.config(), "training": {...}}``);
  ``best.pt``: the weights with the lowest pooled validation BadPix so far.
- ``metrics.jsonl``: one JSON object per log line (``"event": "train"``) and per validation
  (``"event": "validation"``); entries past the checkpoint are dropped on resume.
- TensorBoard event files (``tensorboard --logdir OUT``) and ``learning_curve.png``, from the
  loggers of lfbench.training.curves that see every metrics.jsonl entry;
- ``command.txt``: every command that ran on this folder; ``config.toml``: the config text;
  ``summary.json``: the final numbers; ``data/<category>``: generated synthetic scenes. ``final.pt`` and
  ``summary.json`` are one output set (lfbench.utils.outputs): they appear together, after a kill too.

Samples are a pure function of (seed, stage, step, index) (lfbench.training.data), so a resumed
run and an uninterrupted one see the same batches. On resume only the ``steps`` of the stage in
progress may change (cut a long stage short, or extend it): with a constant learning rate per stage
the result is the run that the new config describes (a network's own schedule continues from its
state). With K processes (torchrun) rank r takes samples [r B/K, (r+1) B/K) of the global batch B,
DistributedDataParallel averages the gradients, and only rank 0 writes files.

This module is the trainer alone; around it, one module per concern: the scenes (``scenes``), the network
and its optimizers (``model``), batches (``batches``), the run folder (``run_folder``), stops (``signals``).
"""

from __future__ import annotations

import contextlib
import functools
import logging
import sys
import time
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import torch
from torch.nn.parallel import DistributedDataParallel
from tqdm import tqdm

from lfbench.method.trainable import check_state_dict, crop_margin, get_trainable, to_channels_last
from lfbench.training import checkpoint as ckpt
from lfbench.training.batches import batch_source
from lfbench.training.config import TrainConfig, resume_view
from lfbench.training.curves import MAX_LOG_BYTES, RunLogger, default_loggers, parse_log_line
from lfbench.training.data import PatchSampler, ValidationScene, load_scene_data, load_validation_scene
from lfbench.training.distributed import DistContext, agree_on_resume, match_grad_strides, setup
from lfbench.training.losses import make_loss
from lfbench.training.model import (
    build_model,
    check_model,
    describe_optimizer,
    load_init_weights,
    network_config,
    stage_optimizer,
)
from lfbench.training.run_folder import EXPORTS, RunPaths, check_resume_state, run_folder_lock
from lfbench.training.scenes import (
    check_angular_size,
    check_data,
    discover,
    invalid_area,
    prepare_synthetic,
    select_scenes,
)
from lfbench.training.signals import StopFlag, TrainingInterrupted
from lfbench.training.validate import check_validation_area, validate
from lfbench.utils.atomic import write_text
from lfbench.utils.errors import DataError, LFBenchError, SpecError
from lfbench.utils.hardware import require_bf16, set_fp32_numerics
from lfbench.utils.jsonfile import json_text, read_json
from lfbench.utils.malloc import retain_freed_memory
from lfbench.utils.outputs import check_output_entries, read_manifest, recover, staged_outputs
from lfbench.utils.readfile import read_text
from lfbench.utils.threads import torch_threads
from lfbench.utils.tomlfile import MAX_TOML_BYTES

_log = logging.getLogger(__name__)


class Trainer:
    def __init__(self, cfg: TrainConfig, out: Path, ctx: DistContext, command: str | None = None,
                 progress: bool | None = None, loggers: Sequence[RunLogger] = ()) -> None:
        self.cfg, self.ctx, self.paths = cfg, ctx, RunPaths(Path(out))
        self.trainable = get_trainable(cfg.method)  # its training_forward: the target to a network that takes it
        self.loggers = list(loggers) if ctx.is_main else []  # see every metrics.jsonl entry
        self.command = command
        self.progress = progress
        self.stop = StopFlag()
        self.best_badpix = float("inf")
        self.last_validation: dict | None = None
        self.elapsed_before = 0.0
        self.t0 = time.perf_counter()
        self.global_step = 0
        self.init_info: dict | None = None  # {"path", "sha256"} of cfg.init once loaded (also kept on resume)
        self.schedule_state: dict | None = None  # a resumed learning-rate schedule's state
        self.schedule = None  # the learning-rate schedule of the stage in progress (None: a constant rate)
        self._stride_hooks: list = []  # gradient hooks of the DDP wrapping the model now (match_grad_strides)

    # -- output ------------------------------------------------------------------------------

    def log(self, msg: str) -> None:
        """A line of the training log (logger ``lfbench.training.loop``; the CLI shows it on stderr, an
        ablation cell writes it to its log.txt)."""
        if self.ctx.is_main:
            _log.info(msg)

    def record(self, entry: dict) -> None:
        if self.ctx.is_main:
            with open(self.paths.metrics, "a", encoding="utf-8") as f:
                f.write(json_text(entry, sort_keys=True) + "\n")
            for logger in self.loggers:
                logger.record(entry)

    def elapsed(self) -> float:
        return self.elapsed_before + time.perf_counter() - self.t0

    def _truncate_metrics(self, global_step: int) -> None:
        """Drop log entries written after the checkpoint (they will be written again)."""
        p = self.paths.metrics
        if not p.is_file():
            return
        kept = []
        for line in read_text(p, "training log", MAX_LOG_BYTES, errors="replace").splitlines():
            entry = parse_log_line(line)  # None: a line cut by the kill
            step = entry.get("global_step", 0) if entry is not None else None
            if isinstance(step, int | float) and step <= global_step:
                kept.append(line)
        write_text(p, "".join(k + "\n" for k in kept))

    def _record_command(self, resumed: bool) -> None:
        stamp = time.strftime("%Y-%m-%d %H:%M:%S")
        line = f"# {stamp} world_size={self.ctx.world_size}{' (resumed)' if resumed else ''}\n{self.command or ''}\n"
        old = read_text(self.paths.command, "command log", MAX_LOG_BYTES, errors="replace") \
            if self.paths.command.is_file() else ""
        write_text(self.paths.command, old + line)

    # -- state -------------------------------------------------------------------------------

    def _checkpoint_payload(self, model, optimizer, stage: int, step: int) -> dict:
        payload = {
            "format": ckpt.CHECKPOINT_FORMAT, "version": ckpt.VERSION,
            "config": self.cfg.to_dict(), "stage": stage, "step": step, "global_step": self.global_step,
            "model": {k: v.detach().cpu() for k, v in model.state_dict().items()},
            "optimizer": optimizer.state_dict() if optimizer is not None else None,
            "rng": ckpt.rng_state(), "elapsed_s": self.elapsed(), "world_size": self.ctx.world_size,
            "best_badpix": self.best_badpix, "last_validation": self.last_validation, "init": self.init_info,
        }
        if optimizer is not None and self.schedule is not None:  # a trainable's own schedule, within a stage
            payload["schedule"] = self.schedule.state_dict()
        return payload

    def save_checkpoint(self, model, optimizer, stage: int, step: int) -> None:
        if self.ctx.is_main:
            ckpt.save(self.paths.checkpoint, self._checkpoint_payload(model, optimizer, stage, step))

    def load_checkpoint(self) -> dict | None:
        """The checkpoint to resume from (type-checked), or None. Only what the finished stages and the
        stage in progress used must be the same: a later stage may be fixed or added before it starts."""
        if not self.paths.checkpoint.is_file():
            return None
        state = ckpt.load(self.paths.checkpoint, ckpt.CHECKPOINT_FORMAT)
        check_resume_state(state, self.paths.checkpoint)
        in_progress = state["stage"] if state["step"] > 0 else None
        used = state["stage"] + (1 if in_progress is not None else 0)
        if resume_view(state["config"], used, in_progress) != resume_view(self.cfg.to_dict(), used, in_progress):
            raise SpecError(f"the config differs from the one {self.paths.checkpoint} was trained with (in a "
                            f"setting or one of the {used} stage(s) already trained; only the steps of the stage "
                            "in progress may change); use another --out folder to start a new run", self.cfg.source)
        return state

    def export(self, path: Path, model, info: dict | None = None) -> None:
        """Write inference weights (runnable as ``<method>:weights=PATH``)."""
        ckpt.export_weights(path, model, info if info is not None else self.training_info(),
                            method=get_trainable(self.cfg.method).method_name, config=network_config(self.cfg, model))

    def training_info(self) -> dict:
        info = {"command": self.command, "config": self.cfg.to_dict(), "steps": self.global_step,
                "elapsed_s": self.elapsed(), "world_size": self.ctx.world_size,
                "validation": self.last_validation, "torch": str(torch.__version__)}
        if self.init_info is not None:
            info["init"] = self.init_info
        return info

    # -- validation ----------------------------------------------------------------------------

    def run_validation(self, model, scenes: list[ValidationScene], stage: int, step: int) -> None:
        if self.ctx.is_main and scenes:
            v = self.cfg.validation
            start = time.perf_counter()
            res = validate(model, scenes, self.ctx.device, border=v.border, threshold=v.threshold,
                           scorer=v.scorer)
            res.update(event="validation", stage=stage + 1, stage_name=self.cfg.stages[stage].name, step=step,
                       global_step=self.global_step, seconds=round(time.perf_counter() - start, 3))
            self.last_validation = res
            self.record(res)
            per = ", ".join(f"{n} {s['badpix']:.2f}/{s['mse_x100']:.3f}" for n, s in res["scenes"].items())
            self.log(f"[validation] step {self.global_step}: BadPix({v.threshold:g}) {res['badpix']:.2f} %, "
                     f"MSE x100 {res['mse_x100']:.3f} ({per})")
            if res["badpix"] < self.best_badpix:
                self.best_badpix = res["badpix"]
                self.export(self.paths.best, model)
        self.ctx.barrier()

    # -- main: setup, resume, build, fit, export --------------------------------------------------

    def run(self, require_checkpoint: bool = False) -> dict:
        """Train (or resume) the config's stages and export the final weights; returns a summary."""
        local_batch = self._setup()
        state = self._resume_state(require_checkpoint)
        init = load_init_weights(self.cfg) if state is None and self.cfg.init else None  # checked before any work
        paths = self.paths
        if state is not None and state["stage"] >= len(self.cfg.stages) and paths.final.is_file() \
                and paths.summary.is_file():
            changed = self._exports_changed(state)
            if changed is None:
                self.log(f"{paths.out}: training already complete ({state['global_step']} steps); final weights in "
                         f"{paths.final}")
                return {"final": str(paths.final), "steps": state["global_step"], "resumed": True}
            self.log(f"{changed}: re-exported from {paths.checkpoint}")
        self._prepare_folder(state)
        sampler, validation = self._load_data()
        model = self._build(sampler, init)
        start_stage, start_step, opt_state = self._restore(model, state)
        self._place(model)
        self._fit(model, sampler, validation, start_stage, start_step, opt_state, local_batch)
        return self._export_final(model, resumed=state is not None)

    def _exports_changed(self, state: dict) -> str | None:
        """Why the finished run's final.pt / summary.json are not what its checkpoint ended with (None when they
        are): the weights' state dict must be the checkpoint's model (``state_sha256``), of this config's network,
        and the summary must count the checkpoint's steps. A file copied over from another run is re-exported."""
        paths = self.paths
        try:
            final = ckpt.load(paths.final, ckpt.WEIGHTS_FORMAT)
            summary = read_json(paths.summary, "training summary")
        except LFBenchError as exc:
            return str(exc)
        if not isinstance(final.get("state_dict"), dict) or \
                ckpt.state_sha256(final["state_dict"]) != ckpt.state_sha256(state["model"]):
            return f"{paths.final} does not hold the weights of {paths.checkpoint}"
        if final.get("method") != get_trainable(self.cfg.method).method_name:
            return f"{paths.final} holds another network's weights"
        if not isinstance(summary, dict) or summary.get("steps") != state["global_step"]:
            return f"{paths.summary} does not record the {state['global_step']} steps of {paths.checkpoint}"
        return None

    def _setup(self) -> int:
        """Thread count; the samples of a step per process (the batch must split over processes and micro-batches)."""
        cfg, tc, world = self.cfg, self.cfg.training, self.ctx.world_size
        if tc.threads:
            torch.set_num_threads(tc.threads)
        local_batch, rem = divmod(tc.batch_size, world)
        if rem or local_batch % tc.accumulate:
            raise SpecError(f"training.batch_size {tc.batch_size} must split evenly over {world} "
                            f"process(es) x accumulate {tc.accumulate}", cfg.source)
        return local_batch

    def _resume_state(self, require_checkpoint: bool) -> dict | None:
        """The checkpoint to resume from (None: a new run), the same on every process (or one error everywhere)."""
        ctx, paths = self.ctx, self.paths
        try:
            if ctx.is_main:
                recover(paths.out)  # an export cut short by a kill is finished first (a foreign journal refused)
                read_manifest(paths.out, EXPORTS)
            state = self.load_checkpoint()
            position = None if state is None else (int(state["stage"]), int(state["step"]),
                                                   int(state["global_step"]))
        except LFBenchError as exc:
            state, position = None, exc
        agree_on_resume(ctx, position)  # every rank from the same step, or one error everywhere (no hang)
        if state is None and require_checkpoint:
            raise DataError("--resume given but there is no checkpoint to resume from", paths.checkpoint)
        return state

    def _prepare_folder(self, state: dict | None) -> None:
        """config.toml, command.txt, metrics.jsonl (emptied, or cut at the checkpoint) and the synthetic data."""
        cfg, paths = self.cfg, self.paths
        if self.ctx.is_main:
            paths.out.mkdir(parents=True, exist_ok=True)
            if cfg.source and Path(cfg.source).is_file():
                write_text(paths.config, read_text(cfg.source, "config file", MAX_TOML_BYTES, error=SpecError))
            self._record_command(resumed=state is not None)
            if state is None:
                write_text(paths.metrics, "")
            else:
                self._truncate_metrics(state["global_step"])
            prepare_synthetic(cfg, paths.data, self.log)
        self.ctx.barrier()

    def _load_data(self) -> tuple[PatchSampler, list[ValidationScene]]:
        """The patch sampler over the training scenes and the validation scenes (loaded on rank 0 only)."""
        cfg = self.cfg
        bench = discover(cfg, self.paths.data)
        train_scenes, val_scenes = select_scenes(bench, cfg)
        check_angular_size([*train_scenes, *val_scenes])  # the generated sets too
        check_validation_area(val_scenes, cfg.validation.border, cfg.validation.max_size, cfg.source)
        masks = invalid_area(cfg)
        unknown = set(cfg.data.scene_weights) - {s.name for s in train_scenes}
        if unknown:
            self.log(f"warning: data.scene_weights names no training scene: {', '.join(sorted(unknown))}")
        self.log(f"training scenes ({len(train_scenes)}): {', '.join(s.name for s in train_scenes)}")
        if val_scenes:
            self.log(f"validation scenes ({len(val_scenes)}): {', '.join(s.name for s in val_scenes)}")
        sampler = PatchSampler([load_scene_data(s, masks) for s in train_scenes], cfg.data, cfg.augment)
        validation = ([load_validation_scene(s, cfg.validation.max_size) for s in val_scenes]
                      if self.ctx.is_main else [])
        return sampler, validation

    def _build(self, sampler: PatchSampler, init: tuple[Path, dict] | None) -> torch.nn.Module:
        """The network, seeded by the config (and loaded with the init weights), for the scenes' views."""
        cfg = self.cfg
        torch.manual_seed(cfg.seed)
        np.random.seed(cfg.seed % 2**32)
        model = build_model(cfg)
        angular = int(getattr(model, "angular", 9))
        if angular != sampler.angular[0] or sampler.angular[0] != sampler.angular[1]:
            raise DataError(f"the scenes have {sampler.angular[0]}x{sampler.angular[1]} views, the model expects "
                            f"{angular}x{angular}", cfg.source)
        if init is not None:
            path, weights = init
            check_state_dict(weights, model.state_dict(), path, "init weights")
            model.load_state_dict(weights)
            self.init_info = {"path": str(path), "sha256": ckpt.state_sha256(weights)}
            self.log(f"starting from the weights {path}")
        return model

    def _restore(self, model: torch.nn.Module, state: dict | None) -> tuple[int, int, dict | None]:
        """Load a checkpoint's weights, counters and RNG states: (stage, step, optimizer state) to go on from."""
        if state is None:
            return 0, 0, None
        cfg, paths = self.cfg, self.paths
        check_state_dict(state["model"], model.state_dict(), paths.checkpoint, "training checkpoint model")
        model.load_state_dict(state["model"])
        start_stage, start_step = state["stage"], state["step"]
        done = start_stage == len(cfg.stages) and start_step == 0  # finished, final weights not yet written
        if not done and (start_stage >= len(cfg.stages) or start_step > cfg.stages[start_stage].steps):
            raise DataError(f"training checkpoint is at stage {start_stage + 1} step {start_step}, beyond the "
                            "config's stages", paths.checkpoint)  # steps == the stage's steps: it ends now
        self.global_step = state["global_step"]
        self.elapsed_before = float(state["elapsed_s"])
        self.best_badpix = float(state["best_badpix"])
        self.last_validation = state["last_validation"]
        init_info = state.get("init")
        self.init_info = init_info if isinstance(init_info, dict) else None
        self.schedule_state = state.get("schedule")
        try:
            ckpt.set_rng_state(state["rng"])
        except (KeyError, TypeError, ValueError, AttributeError, RuntimeError, IndexError):
            raise DataError("training checkpoint has an unusable RNG state", paths.checkpoint) from None
        self.log(f"resuming from {paths.checkpoint}: stage {start_stage + 1}, step {start_step} "
                 f"(global step {self.global_step})")
        return start_stage, start_step, state["optimizer"]

    def _place(self, model: torch.nn.Module) -> None:
        """The model on the device in training mode, in its memory format, with the numerics the config asks."""
        ctx, tc = self.ctx, self.cfg.training
        model.to(ctx.device).train()
        if tc.channels_last:
            to_channels_last(model)
        if tc.precision == "bf16":
            require_bf16(ctx.device, "training.precision = 'bf16'")  # one line on a CPU without bf16
        if ctx.device.type == "cuda":
            set_fp32_numerics(tf32=tc.tf32)  # IEEE fp32 unless training.tf32 = true
            torch.backends.cudnn.benchmark = tc.cudnn_benchmark

    def _fit(self, model, sampler: PatchSampler, validation: list[ValidationScene], start_stage: int,
             start_step: int, opt_state: dict | None, local_batch: int) -> None:
        self.t0 = time.perf_counter()  # elapsed_s counts training (and validation), not data loading
        with self.stop.installed():
            for si in range(start_stage, len(self.cfg.stages)):
                first = si == start_stage
                self._run_stage(model, sampler, validation, si, start_step if first else 0,
                                opt_state if first else None, local_batch)

    def _export_final(self, model, resumed: bool) -> dict:
        """final.pt and summary.json as one output set (rank 0), after the ranks agreed on the weights."""
        ctx, paths = self.ctx, self.paths
        result = {"final": str(paths.final), "steps": self.global_step, "resumed": resumed,
                  "elapsed_s": self.elapsed()}
        digests = ctx.gather(ckpt.parameters_sha256(model))  # DDP: identical on every rank
        ctx.broadcast_buffers(model)
        if ctx.is_main:
            info = self.training_info()
            info["rank_parameters_sha256"] = digests
            summary = {k: v for k, v in info.items() if k != "config"}
            with staged_outputs(paths.out, EXPORTS) as outputs:  # final.pt and summary.json: one set
                self.export(outputs.stage / paths.final.name, model, info)
                write_text(outputs.stage / paths.summary.name, json_text(summary, indent=2, sort_keys=True) + "\n")
                outputs.commit([paths.final.name, paths.summary.name])
            self.log(f"done: {self.global_step} steps in {self.elapsed():.1f} s; final weights {paths.final}")
        result["rank_parameters_sha256"] = digests
        return result

    # -- one stage -------------------------------------------------------------------------------

    def _optimizer(self, model, si: int, opt_state: dict | None):
        """The stage's fresh optimizer and schedule (the trainable's), with a checkpoint's states when resuming."""
        optimizer, schedule = stage_optimizer(self.cfg, model, si)
        if opt_state is None:
            return optimizer, schedule
        try:
            optimizer.load_state_dict(opt_state)
            for group in optimizer.param_groups:
                for p in group["params"]:
                    for value in optimizer.state.get(p, {}).values():
                        if isinstance(value, torch.Tensor) and value.ndim and value.shape != p.shape:
                            raise ValueError("shape")
            if schedule is not None and self.schedule_state is not None:
                schedule.load_state_dict(self.schedule_state)
        except (KeyError, TypeError, ValueError, AttributeError, RuntimeError, IndexError):
            raise DataError("training checkpoint has an optimizer state that does not fit the model",
                            self.paths.checkpoint) from None
        return optimizer, schedule

    def _parallel(self, model):
        """The module the steps call: DistributedDataParallel over the processes, else the model itself."""
        if not self.ctx.enabled:
            return model
        device = self.ctx.device
        for handle in self._stride_hooks:  # the previous stage's, for the strides its DDP compared
            handle.remove()
        self._stride_hooks = match_grad_strides(model)  # 1x1 weights: no stride warning, no gradient copy per step
        return DistributedDataParallel(model, device_ids=[device.index] if device.type == "cuda" else None)

    def _progress(self, st, step: int, label: str):
        if not self.ctx.is_main:
            disable: bool | None = True
        else:
            disable = None if self.progress is None else not self.progress  # None: only on a terminal
        return tqdm(total=st.steps, initial=step, desc=label, disable=disable, dynamic_ncols=True, leave=False,
                    file=sys.stderr)

    def _run_stage(self, model, sampler: PatchSampler, validation: list[ValidationScene], si: int, step: int,
                   opt_state: dict | None, local_batch: int) -> None:
        cfg, ctx = self.cfg, self.ctx
        st, tc = cfg.stages[si], cfg.training
        loss_fn = make_loss(st.loss, **st.loss_params)
        optimizer, schedule = self._optimizer(model, si, opt_state)
        self.schedule = schedule
        net = self._parallel(model)
        micro = local_batch // tc.accumulate
        label = f"stage {si + 1}/{len(cfg.stages)} {st.name}"
        self.log(f"[{label}] loss {loss_fn.__name__}, {describe_optimizer(optimizer)}, {st.steps} steps of batch "
                 f"{tc.batch_size} ({ctx.world_size} process(es) x {tc.accumulate} micro-batch(es) of {micro}), "
                 f"patch {cfg.data.patch}, from step {step}")
        pinned = tc.pin_memory and ctx.device.type == "cuda"
        margin = get_trainable(cfg.method).output_margin(model)  # the border the network fills: not in the loss
        batches = batch_source(sampler, cfg, si, step, st.steps, ctx.rank * local_batch, local_batch, pinned)
        bar = self._progress(st, step, label)
        window = _Window()
        try:
            while step < st.steps:
                step_loss = self._step(net, model, optimizer, loss_fn, batches.get(step), micro, pinned, margin)
                if ctx.any(not np.isfinite(step_loss)):
                    raise LFBenchError(f"the loss became {step_loss} at stage {si + 1} step {step + 1}; "
                                       f"lower the learning rate (the last checkpoint is {self.paths.checkpoint})")
                lr = optimizer.param_groups[0]["lr"]  # the rate this step used
                optimizer.step()
                if schedule is not None:
                    schedule.step()
                step += 1
                self.global_step += 1
                window.add(step_loss)
                bar.update(1)
                if step % tc.log_every == 0 or step == st.steps:
                    self._log_window(window, bar, si, step, lr, label)
                self._after_step(model, optimizer, validation, si, step)
        finally:
            bar.close()
            batches.close()
        self._finish_stage(model, validation, si)
        if si + 1 < len(cfg.stages) and ctx.any(self.stop.set):
            self._interrupted(si + 1, 0)

    def _step(self, net, model, optimizer, loss_fn, batch, micro: int, pinned: bool, margin: int = 0) -> float:
        """Forward and backward of one step's batch (in ``accumulate`` micro-batches); returns its loss, taken
        over the inner part of the patch (``margin`` px cut per side: the border the network fills)."""
        ctx, tc = self.ctx, self.cfg.training
        views, target = batch
        v, t = torch.as_tensor(views), torch.as_tensor(target)
        if pinned and not v.is_pinned():
            v, t = v.pin_memory(), t.pin_memory()
        v = v.to(ctx.device, non_blocking=pinned)  # page-locked: the copy overlaps the GPU's work
        t = t.to(ctx.device, non_blocking=pinned)
        disparities = getattr(model, "disparities", None)  # what the distribution is over (distribution losses)
        autocast = (functools.partial(torch.autocast, ctx.device.type, dtype=torch.bfloat16)
                    if tc.precision == "bf16" else contextlib.nullcontext)
        optimizer.zero_grad(set_to_none=True)
        step_loss = 0.0
        for m in range(tc.accumulate):
            sl = slice(m * micro, (m + 1) * micro)
            sync = contextlib.nullcontext() if (not ctx.enabled or m == tc.accumulate - 1) else net.no_sync()
            with sync:
                with autocast():  # bf16 forward when training.precision = 'bf16'; the loss in fp32
                    disp, prob = self.trainable.training_forward(net, v[sl], t[sl])
                disp, prob = disp.float(), None if prob is None else prob.float()
                disp, prob, target = crop_margin(disp, prob, t[sl], margin)
                loss = loss_fn(disp, prob, target, disparities) / tc.accumulate
                loss.backward()
            step_loss += float(loss.detach())
        return step_loss

    def _log_window(self, window: _Window, bar, si: int, step: int, lr: float, label: str) -> None:
        """A train entry of metrics.jsonl and a log line: the mean loss and the speed since the last one."""
        st = self.cfg.stages[si]
        mean_loss = self.ctx.mean(window.loss / window.n)
        rate = window.n / max(time.perf_counter() - window.t0, 1e-9)
        bar.set_postfix(loss=f"{mean_loss:.4f}")
        self.record({"event": "train", "stage": si + 1, "stage_name": st.name, "step": step,
                     "global_step": self.global_step, "loss": mean_loss, "lr": lr,
                     "steps_per_s": rate, "elapsed_s": round(self.elapsed(), 3)})
        self.log(f"[{label}] step {step}/{st.steps} loss {mean_loss:.5f} ({rate:.2f} steps/s, "
                 f"{self.elapsed():.0f} s)")
        window.reset()

    def _after_step(self, model, optimizer, validation: list[ValidationScene], si: int, step: int) -> None:
        """Validation every validation.every steps, a checkpoint every training.checkpoint_every steps and on a
        stop signal (then TrainingInterrupted); the stage's end is :meth:`_finish_stage`'s."""
        cfg = self.cfg
        steps = cfg.stages[si].steps
        if cfg.validation.every and step % cfg.validation.every == 0 and step < steps:
            self.run_validation(model, validation, si, step)
        stop = self.ctx.any(self.stop.set)
        if step < steps and (step % cfg.training.checkpoint_every == 0 or stop):
            self.save_checkpoint(model, optimizer, si, step)
            if stop:
                self._interrupted(si, step)

    def _interrupted(self, si: int, step: int) -> None:
        self.ctx.barrier()
        raise TrainingInterrupted(f"stopped at stage {si + 1} step {step}; checkpoint written to "
                                  f"{self.paths.checkpoint}; run the same command to resume")

    def _finish_stage(self, model, validation: list[ValidationScene], si: int) -> None:
        """End of stage: validate, export its weights, checkpoint at (next stage, step 0)."""
        st = self.cfg.stages[si]
        last = self.last_validation
        if last is None or last.get("global_step") != self.global_step:  # a stage cut on resume: done already
            self.run_validation(model, validation, si, st.steps)
        if self.ctx.is_main:
            self.export(self.paths.stage_weights(si, st.name), model)
        self.save_checkpoint(model, None, si + 1, 0)
        self.ctx.barrier()


class _Window:
    """The losses summed since the last log line, their count and when the window started."""

    def __init__(self) -> None:
        self.reset()

    def add(self, loss: float) -> None:
        self.loss += loss
        self.n += 1

    def reset(self) -> None:
        self.loss, self.n, self.t0 = 0.0, 0, time.perf_counter()


def train(cfg: TrainConfig, out: str | Path, *, require_checkpoint: bool = False, command: str | None = None,
          progress: bool | None = None, loggers: Sequence[RunLogger] | None = None) -> dict:
    """Train per ``cfg`` into ``out`` (resuming from out/checkpoint.pt when present); returns a summary.
    ``loggers`` see every metrics.jsonl entry and are closed when the run stops (default:
    TensorBoard event files and the PNG learning curve, lfbench.training.curves.default_loggers).
    The [model] values and the data are checked first (:func:`check_model`, :func:`check_data`): a bad
    config is one error with nothing generated or written.

    Run under torchrun for data-parallel training; every process calls this function.
    """
    check_model(cfg)
    check_data(cfg, RunPaths(Path(out)).data)
    check_output_entries(Path(out))  # no device, FIFO or socket where the run writes its files
    retain_freed_memory()  # fewer page faults per step (glibc); results unchanged
    with torch_threads(None):  # the run sets its own thread count; the caller's comes back afterwards
        ctx = setup(cfg.training.device)
        try:
            with run_folder_lock(Path(out)) if ctx.is_main else contextlib.nullcontext():
                if loggers is None:
                    loggers = default_loggers(Path(out)) if ctx.is_main else []
                try:
                    return Trainer(cfg, Path(out), ctx, command, progress, loggers).run(require_checkpoint)
                finally:
                    for logger in loggers:
                        logger.close()
        finally:
            ctx.close()


