"""Training throughput and hardware utilisation of every trainable network, float32 and bf16-mixed side by side.

For each network: FLOPs per sample of one optimiser step (forward + backward, counted by
``torch.utils.flop_counter.FlopCounterMode``), samples/s, and the achieved FLOP/s as a share of this run's own
2048×2048 matmul peak for the dtype used (float32 for ``32-true``, bfloat16 for ``bf16-mixed``, which runs under
``torch.autocast`` as Lightning's ``bf16-mixed`` does), so the share means the same on any machine.

* **Model step** (table 1): one fixed batch, forward + loss + backward + optimiser step, mean over ``--steps``
  after a warm-up. The graph networks and the energy-image CNNs read NTU-shaped skeletons (100 frames, 2 bodies,
  25 joints, batch 32; VGG16 at batch 2) with cross-entropy; the gait CNN reads random GEIs at its default size;
  the refiners, the Kinect corrector, the retrieval encoder and the CVAE run their own LightningModule's
  ``training_step`` on a real batch of their experiment's data module (HDM05 cuts, ``../shared/data``).
  FLOPs of the GRU networks are counted on today's step (torch's GRU): their recurrence now runs in numba,
  which the counter does not see.
* **Today vs now**: the graph network and the energy-image CNN are also measured with the implementation before
  the fast rewrite (``tests/models/reference_*.py``, the equivalence tests' references), the gait CNN with
  torch's ``LocalResponseNorm``, and the refiners, the Kinect corrector, the retrieval encoder and the CVAE with
  torch's own GRU, transformer layer, vector norm, ELU, dropout and Adam update (:func:`_torch_own_modules`), loaded
  with the same weights and the same batch, their steps alternating with the new ones (``--steps`` turns each,
  a turn at least 0.25 s of steps, the median turn reported), so "now / today" is a ratio from one run under the
  same load.
* **Loop with data loading** (table 2): the experiment's own ``train_dataloader`` over real cached data
  (MSR Action3D, HDM05; the demo's NTU-format cache when ``.demo/ntu_cache`` exists) timed together with the
  step, against the step alone on the same batches; ``loop / step`` near 1 means the loop is not data-bound.

Usage: ``python bench/bench_training.py [--models stgcn energy_vgg_cpu ...] [--quick] [--steps 3]``;
``--list`` names the networks. Timings are ratios within the run: on a shared machine, compare columns, not runs.
"""

from __future__ import annotations

import argparse
import contextlib
import itertools
import os
import platform
import statistics
import sys
import time
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import torch
import torch.nn.functional as F
from torch.utils.flop_counter import FlopCounterMode

ROOT = Path(__file__).resolve().parents[1]
SHARED = Path(os.environ.get("MOCAPKIT_SHARED", ROOT.parent / "shared"))
PRECISIONS = ("32-true", "bf16-mixed")
ROUND_SECONDS = 0.25  # the shortest turn of steps when today and now alternate


def reference(name: str):
    """``tests/models/reference_<name>.py`` (today's implementation), loaded from its file."""
    import importlib.util

    path = ROOT / "tests" / "models" / f"reference_{name}.py"
    spec = importlib.util.spec_from_file_location(f"reference_{name}", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def matmul_peak(dtype: torch.dtype, size: int = 2048, repeats: int = 5) -> float:
    """FLOP/s of the best of ``repeats`` ``size × size`` matmuls in ``dtype``."""
    a, b = torch.randn(size, size, dtype=dtype), torch.randn(size, size, dtype=dtype)
    a @ b
    best = float("inf")
    for _ in range(repeats):
        start = time.perf_counter()
        a @ b
        best = min(best, time.perf_counter() - start)
    return 2 * size**3 / best


def autocast(precision: str):
    if precision == "bf16-mixed":
        return torch.autocast("cpu", dtype=torch.bfloat16)
    return contextlib.nullcontext()


@dataclass
class Case:
    """One network: ``build()`` → ``(step_fn(batch), batches, samples_per_batch)``."""

    name: str
    build: object
    note: str = ""
    today: object = None  # build() of today's implementation, same weights; None: not rewritten
    flops_on_today: bool = False  # count FLOPs on today's step: the new one runs products FlopCounterMode misses
    loop: object = None  # build() → (step_fn, dataloader, batch augmentation) for the data-loading table
    extra: dict = field(default_factory=dict)


def _optimizer_step(model, loss_fn, optimizer):
    def step(batch, precision):
        with autocast(precision):
            loss = loss_fn(model, batch)
        optimizer.zero_grad(set_to_none=True)
        loss.backward()
        optimizer.step()

    return step


def _skeleton_classifier(model_name: str, batch: int, overrides=(), reference=None):
    """A recognition network on NTU-shaped skeletons (100 frames, 2 bodies), cross-entropy, the model's optimiser."""

    def build(frames: int = 100, compiled: bool = False):
        from hydra.utils import instantiate

        from mocapkit.recognition.export import example_skeletons
        from mocapkit.train.config import compose_config

        cfg = compose_config([f"model={model_name}", *overrides])
        torch.manual_seed(0)
        model = instantiate(cfg.model, num_classes=60).train()
        if reference is not None:
            model = reference(cfg.model, model)
        optimizer = torch.optim.SGD(model.parameters(), lr=0.01, momentum=0.9)
        x, y = example_skeletons(batch, frames), torch.randint(0, 60, (batch,))
        if compiled:
            model = torch.compile(model)

        def loss_fn(m, b):
            out = m(b[0])
            if out.dim() == 3:  # the ensemble in training mode: one logit set per member
                return sum(F.cross_entropy(o, b[1]) for o in out)
            return F.cross_entropy(out, b[1])

        return _optimizer_step(model, loss_fn, optimizer), [(x, y)], batch

    return build


def _reference_stgcn(cfg_model, model):
    """Today's ST-GCN (tests/models/reference_stgcn.py) with the new module's weights."""
    from omegaconf import OmegaConf

    reference_stgcn = reference("stgcn")
    kwargs = {k: v for k, v in OmegaConf.to_container(cfg_model, resolve=True).items() if not k.startswith("_")}
    builder = reference_stgcn.stgcn_ensemble if "ensemble" in cfg_model._target_ else reference_stgcn.stgcn
    old = builder(num_classes=60, **kwargs).train()
    old.load_state_dict(model.state_dict())
    return old


def _reference_energy(cfg_model, model):
    """The energy-image classifier with today's energy image (tests/models/reference_energy_image.py)."""
    model.energy = reference("energy_image").reference_like(model.energy)
    return model


def _gait_cnn(batch: int = 32, torch_lrn: bool = False):
    """The multi-task gait CNN on random GEIs; ``torch_lrn``: today's network, with torch's LocalResponseNorm and the
    contiguous layout, same weights (the LRN has none)."""

    def build(compiled: bool = False):
        from hydra.utils import instantiate

        from mocapkit.models.gait_cnn import ChannelWindowLRN
        from mocapkit.train.config import compose_config

        cfg = compose_config(["model=gait_cnn"])
        torch.manual_seed(0)
        model = instantiate(cfg.model, num_subjects=74).train()
        for name, m in model.trunk.named_children():
            if torch_lrn and isinstance(m, ChannelWindowLRN):
                setattr(model.trunk, name, torch.nn.LocalResponseNorm(m.size, alpha=m.alpha, beta=m.beta, k=m.k))
        if torch_lrn:
            model = reference("gait_cnn").make_contiguous(model)
        optimizer = torch.optim.AdamW(model.parameters(), lr=1e-3)
        h, w = model.input_size
        if compiled:
            model = torch.compile(model)
        geis = torch.rand(batch, 1, h, w)
        labels = {"subject": torch.randint(0, 74, (batch,)), "view": torch.randint(0, 11, (batch,))}
        labels["condition"] = torch.randint(0, 3, (batch,))

        def loss_fn(m, b):
            out = m(b[0])
            return sum(F.cross_entropy(out[t], y) for t, y in b[1].items() if t in out)

        return _optimizer_step(model, loss_fn, optimizer), [(geis, labels)], batch

    return build


def _experiment_parts(experiment: str, overrides=()):
    """The experiment's data module (set up for fitting), LightningModule and first optimiser."""
    from mocapkit.train.config import compose_config
    from mocapkit.train.training import build, build_datamodule

    cfg = compose_config([f"experiment={experiment}", *overrides])
    datamodule = build_datamodule(cfg)
    datamodule.setup("fit")
    module = build(cfg.module, **datamodule.label_spaces())
    module.train()
    configured = module.configure_optimizers()
    if isinstance(configured, dict):
        optimizer = configured["optimizer"]
    elif isinstance(configured, list | tuple):
        optimizer = configured[0][0] if isinstance(configured[0], list | tuple) else configured[0]
        optimizer = optimizer["optimizer"] if isinstance(optimizer, dict) else optimizer
    else:
        optimizer = configured
    return datamodule, module, optimizer


def _batch_size(batch) -> int:
    if isinstance(batch, torch.Tensor):
        return batch.shape[0]
    if isinstance(batch, dict):
        return _batch_size(next(v for v in batch.values() if isinstance(v, torch.Tensor)))
    return _batch_size(batch[0])


def _lightning_step(experiment: str, overrides=(), batches: int = 1):
    """``training_step`` of the experiment's own LightningModule on real batches of its data module."""

    def parts():
        datamodule, module, optimizer = _experiment_parts(experiment, overrides)

        def loss_fn(m, b):
            out = m.training_step(b, 0)
            return out["loss"] if isinstance(out, dict) else out

        # the skeleton data modules change the view of whole batches in the Trainer's batch hook
        augment = getattr(datamodule, "augment_batch", lambda batch: batch)
        return _optimizer_step(module, loss_fn, optimizer), datamodule.train_dataloader(), augment

    def build():
        step, loader, augment = parts()
        taken = [augment(batch) for batch in itertools.islice(iter(loader), batches)]
        return step, taken, _batch_size(taken[0])

    return build, parts


@contextlib.contextmanager
def _torch_own_modules():
    """Today's refiners, Kinect corrector, retrieval encoder and CVAE: torch's own GRU, transformer layer, vector
    norm, ELU and dropout in place of :mod:`mocapkit.models.gru` and :mod:`mocapkit.models.ops` (looked up at
    call time, so a patched step runs today's code with the same weights)."""
    from unittest import mock

    import mocapkit.models.ops as ops
    import mocapkit.models.refiners as refiners
    import mocapkit.train.refine_module as refine_module

    with (
        mock.patch.object(refiners, "gru_forward", lambda gru, x: gru(x)[0]),
        mock.patch.object(refiners, "encoder_layer_forward", lambda layer, h: layer(h)),
        mock.patch.object(refine_module, "vector_length", lambda x: torch.linalg.vector_norm(x, dim=-1)),
        mock.patch.object(ops.ELU, "forward", lambda self, x: F.elu(x)),
        mock.patch.object(ops.Dropout, "forward", torch.nn.Dropout.forward),
    ):
        yield


def _lightning_step_today(experiment: str, overrides=()):
    """:func:`_lightning_step` as it ran before the training-speed work: torch's own modules
    (:func:`_torch_own_modules`) and the optimiser's for-loop update (``optimizer.fused=false``)."""
    build, _ = _lightning_step(experiment, [*overrides, "++optimizer.fused=false"])

    def today():
        step, batches, size = build()

        def old_step(batch, precision):
            with _torch_own_modules():
                step(batch, precision)

        return old_step, batches, size

    return today


def cases() -> list[Case]:
    msr = [f"data.root={SHARED / 'data' / 'msr_action3d'}"]
    hdm = [f"data.root={SHARED / 'data' / 'hdm05_cuts11'}"]
    quiet = ["trainer.enable_progress_bar=false"]
    out = [
        Case(
            "stgcn",
            _skeleton_classifier("stgcn", 32),
            "graph network, batch 32",
            today=_skeleton_classifier("stgcn", 32, reference=_reference_stgcn),
        ),
        Case(
            "stgcn_ensemble",
            _skeleton_classifier("stgcn_ensemble", 32),
            "4-stream ensemble, batch 32",
            today=_skeleton_classifier("stgcn_ensemble", 32, reference=_reference_stgcn),
        ),
        Case(
            "energy_vgg_cpu",
            _skeleton_classifier("energy_vgg_cpu", 32),
            "energy image + VGG11-BN ¼, 64 px, batch 32",
            today=_skeleton_classifier("energy_vgg_cpu", 32, reference=_reference_energy),
        ),
        Case("energy_vgg16", _skeleton_classifier("energy_vgg16", 2), "thesis VGG16, 224 px, batch 2"),
        Case(
            "gait_cnn",
            _gait_cnn(32),
            "multi-task gait CNN, 124×124 GEIs, batch 32",
            today=_gait_cnn(32, torch_lrn=True),
        ),
    ]
    for name, experiment, note, extra in (
        ("refine_bigru", "refine_bigru", "HDM05 windows of 240 frames, batch 16", hdm),
        ("refine_transformer", "refine_transformer", "HDM05 windows, batch of the experiment", hdm),
        ("kinect_corrector", "kinect_corrector_bigru", "simulated Kinect pairs of HDM05, 64-frame windows", hdm),
        ("motion_encoder", "retrieval_supcon", "retrieval encoder (tcn), HDM05, batch 64", hdm),
        ("motion_vae", "synthesis_cvae", "CVAE, HDM05 frame triples, batch 256", hdm),
    ):
        build, _ = _lightning_step(experiment, [*extra, *quiet])
        today = _lightning_step_today(experiment, [*extra, *quiet])
        # the GRU's recurrence runs compiled by numba (mocapkit.models.gru): counted on torch's GRU, the same products
        out.append(Case(name, build, note, today=today, flops_on_today="bigru" in experiment))
    loops = [
        ("loop: msr3d_gcn (MSR Action3D)", "msr3d_gcn", msr),
        ("loop: hdm05_gcn (HDM05)", "hdm05_gcn", hdm),
    ]
    if (ROOT / ".demo" / "ntu_cache" / "meta.json").exists():
        loops.append(
            ("loop: ntu_energy_vgg (demo NTU cache)", "ntu_energy_vgg", [f"data.root={ROOT / '.demo/ntu_cache'}"])
        )
    for name, experiment, extra in loops:
        _, parts = _lightning_step(experiment, [*extra, *quiet])
        out.append(Case(name, None, experiment, loop=parts))
    return out


def time_steps(step, batches, precision: str, steps: int, warm: bool = True) -> float:
    """Seconds per step: one warm-up (``warm``), then ``steps`` steps cycling over ``batches``."""
    if warm:
        step(batches[0], precision)
    start = time.perf_counter()
    for batch in itertools.islice(itertools.cycle(batches), steps):
        step(batch, precision)
    return (time.perf_counter() - start) / steps


def count_flops(step, batch, precision: str) -> float:
    counter = FlopCounterMode(display=False)
    with counter:
        step(batch, precision)
    return counter.get_total_flops()


def measure(case: Case, steps: int) -> dict:
    """One network's row. The matmul peaks are measured again just before its steps, so the share compares with
    what the machine gave at that moment (on a shared machine the load changes during a run)."""
    row = {"name": case.name, "note": case.note}
    step, batches, size = case.build()
    peaks = {"32-true": matmul_peak(torch.float32), "bf16-mixed": matmul_peak(torch.bfloat16)}
    row["peaks"] = peaks
    row["batch"] = size
    old_step = case.today()[0] if case.today is not None else None
    flops = count_flops(old_step if case.flops_on_today else step, batches[0], "32-true") / size
    row["gflop_per_sample"] = flops / 1e9
    for precision in PRECISIONS:
        if old_step is None:
            seconds = time_steps(step, batches, precision, steps)
        else:  # today and now alternate, so a change of the machine's load hits both alike
            step(batches[0], precision), old_step(batches[0], precision)
            # each turn runs the steps of at least ROUND_SECONDS: single steps of a few ms are mostly noise
            repeats = max(1, round(ROUND_SECONDS / time_steps(old_step, batches, precision, 1, warm=False)))
            turns, old_turns = [], []
            for _ in range(steps):
                turns.append(time_steps(step, batches, precision, repeats, warm=False))
                old_turns.append(time_steps(old_step, batches, precision, repeats, warm=False))
            seconds, old_seconds = statistics.median(turns), statistics.median(old_turns)  # a disturbed turn drops out
            row[f"today {precision}"] = size / old_seconds
        row[precision] = size / seconds
        row[f"{precision} util"] = flops * size / seconds / peaks[precision]
    return row


def measure_compiled(case: Case, steps: int) -> dict:
    """``torch.compile`` (inductor) of the network of ``case``: compile time (the first step, forward and backward)
    and samples/s against eager, both precisions; the optimiser step stays eager."""
    rows = {}
    for precision in PRECISIONS:
        step, batches, size = case.build()
        eager = size / time_steps(step, batches, precision, steps)
        torch._dynamo.reset()
        step_c, batches, size = case.build(compiled=True)
        start = time.perf_counter()
        step_c(batches[0], precision)
        compile_s = time.perf_counter() - start
        rows[precision] = (eager, size / time_steps(step_c, batches, precision, steps), compile_s)
    return rows


def measure_loop(case: Case, steps: int, precision: str) -> dict:
    step, loader, augment = case.loop()
    batches = [augment(batch) for batch in itertools.islice(iter(loader), steps)]
    size = sum(_batch_size(b) for b in batches) / len(batches)
    alone = time_steps(step, batches, precision, len(batches))
    start = time.perf_counter()
    done = 0
    while done < steps:
        for batch in loader:
            step(augment(batch), precision)
            done += 1
            if done == steps:
                break
    looped = (time.perf_counter() - start) / steps
    return {
        "name": case.name,
        "batch": size,
        "workers": loader.num_workers,
        "step": size / alone,
        "loop": size / looped,
        "ratio": looped / alone,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--models", nargs="*", default=None, help="names to run (default: all; --list)")
    parser.add_argument("--steps", type=int, default=2, help="timed steps per measurement (after one warm-up)")
    parser.add_argument("--quick", action="store_true", help="1 timed step, the loop table on 4 batches")
    parser.add_argument("--list", action="store_true", help="print the network names and exit")
    parser.add_argument(
        "--compile", action="store_true", help="only torch.compile against eager for the chosen rewritten networks"
    )
    args = parser.parse_args()
    warnings.filterwarnings("ignore")
    import logging

    logging.getLogger("lightning.pytorch").setLevel(logging.ERROR)
    all_cases = cases()
    if args.list:
        print("\n".join(c.name for c in all_cases))
        return
    chosen = [c for c in all_cases if args.models is None or c.name in args.models or c.note in args.models]
    steps = 1 if args.quick else args.steps
    print(
        f"# training throughput, CPU ({platform.processor() or platform.machine()}, {os.cpu_count()} cores, "
        f"torch {torch.__version__}, {torch.get_num_threads()} threads, "
        f"capability {torch.backends.cpu.get_cpu_capability()}); {steps} timed steps after a warm-up"
    )
    peaks = {"32-true": matmul_peak(torch.float32), "bf16-mixed": matmul_peak(torch.bfloat16)}
    print(
        f"matmul peak (2048×2048) at the start: float32 {peaks['32-true'] / 1e9:.0f} GFLOP/s, "
        f"bfloat16 {peaks['bf16-mixed'] / 1e9:.0f} GFLOP/s (each row's shares use the peaks measured just "
        "before it, its 'peak' column)\n"
    )
    if args.compile:
        print("| network | precision | eager samples/s | compiled samples/s | compiled / eager | compile time (s) |")
        print("|---|---|---:|---:|---:|---:|")
        for case in chosen:
            if case.today is None:  # the rewritten networks only
                continue
            for precision, (eager, compiled, seconds) in measure_compiled(case, steps).items():
                print(
                    f"| `{case.name}` | {precision} | {eager:.1f} | {compiled:.1f} | {compiled / eager:.2f}× "
                    f"| {seconds:.0f} |"
                )
        return
    rows, loops = [], []
    for case in chosen:
        start = time.perf_counter()
        try:
            if case.loop is None:
                rows.append(measure(case, steps))
            else:
                for precision in PRECISIONS:
                    loops.append({**measure_loop(case, 4 if args.quick else 3 * steps, precision), "p": precision})
        except Exception as exc:  # a missing data folder: name it, go on with the others
            print(f"{case.name}: skipped ({type(exc).__name__}: {exc})")
        print(f"[{case.name}: {time.perf_counter() - start:.0f} s]", file=sys.stderr, flush=True)
    if rows:
        print(
            "| network | batch | GFLOP / sample | peak fp32 / bf16 (GFLOP/s) | fp32 samples/s | fp32 % of fp32 peak "
            "| bf16-mixed samples/s | bf16 % of bf16 peak | bf16 / fp32 | today fp32 → now best |"
        )
        print("|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
        for r in rows:
            fp32, bf16 = r["32-true"], r["bf16-mixed"]
            today = (
                f"{r['today 32-true']:.1f} → {max(fp32, bf16):.1f} (**{max(fp32, bf16) / r['today 32-true']:.2f}×**)"
                if "today 32-true" in r
                else "unchanged"
            )
            print(
                f"| `{r['name']}` ({r['note']}) | {r['batch']} | {r['gflop_per_sample']:.2f} "
                f"| {r['peaks']['32-true'] / 1e9:.0f} / {r['peaks']['bf16-mixed'] / 1e9:.0f} | {fp32:.1f} "
                f"| {r['32-true util']:.0%} | {bf16:.1f} | {r['bf16-mixed util']:.0%} | {bf16 / fp32:.2f}× | {today} |"
            )
        todays = [r for r in rows if "today 32-true" in r]
        if todays:
            print("\nToday's implementation, same weights, same run (samples/s):")
            print("| network | today fp32 | today bf16-mixed | now fp32 | now bf16-mixed |")
            print("|---|---:|---:|---:|---:|")
            for r in todays:
                print(
                    f"| `{r['name']}` | {r['today 32-true']:.1f} | {r['today bf16-mixed']:.1f} | {r['32-true']:.1f} "
                    f"| {r['bf16-mixed']:.1f} |"
                )
    if loops:
        print(
            "\n| loop (real data) | precision | batch | workers | step alone, samples/s | loop with loading | loop / step time |"
        )
        print("|---|---|---:|---:|---:|---:|---:|")
        for r in loops:
            print(
                f"| {r['name']} | {r['p']} | {r['batch']:.0f} | {r['workers']} | {r['step']:.1f} | {r['loop']:.1f} "
                f"| {r['ratio']:.2f} |"
            )


if __name__ == "__main__":
    main()
