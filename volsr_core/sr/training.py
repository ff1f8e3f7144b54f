"""The training loop: AdamW + warmup/cosine, AMP on CUDA, checkpoints, exact resume, DDP.

Exact resume: the batch of step k depends only on (seed, k): epoch e = k // steps_per_epoch
shuffles the training samples with generator seed (seed, e), and the dataset seeds each item's
crop and flips with (seed, e, index). A checkpoint holds the model, optimiser, scheduler, AMP
scaler, step and RNG states, so stopping at any checkpoint and resuming reproduces the
uninterrupted run. Under ``torchrun`` (WORLD_SIZE > 1) each rank takes every world-th sample of
each global batch and gradients are averaged by DistributedDataParallel (gloo on CPU, NCCL on CUDA).

One trainer per run folder: rank 0 holds ``OUT/train.lock`` while it trains (:func:`run_folder_lock`).
Resuming takes the newest readable checkpoint: ``last.pt``, else the ``step_*.pt`` files newest first.
"""
from __future__ import annotations

import contextlib
import csv
import math
import os
import random
import sys
import time
from pathlib import Path
from typing import Any, Iterator

import numpy as np
import torch
import torch.distributed as dist
from torch.utils.data import DataLoader, Sampler

from volsr_core.atomic import atomic_write
from volsr_core.errors import InputError, OutputError
from volsr_core.sr.checkpoint import load_checkpoint, load_model, save_checkpoint
from volsr_core.sr.config import TrainingConfig, network_config
from volsr_core.sr.history import history_mode
from volsr_core.sr.loader import SequenceDataset
from volsr_core.sr.losses import ReconstructionLoss, temporal_charbonnier
from volsr_core.sr.metrics import psnr_ssim
from volsr_core.sr.network import SuperResolutionNet, run_unrolled, upsample_motion

LOG_FIELDS = ["step", "epoch", "loss", "lr", "val_psnr", "val_ssim", "seconds"]
LOCK_NAME = "train.lock"


@contextlib.contextmanager
def run_folder_lock(out: Path) -> Iterator[None]:
    """Hold ``out/train.lock`` while training into ``out``: an exclusive ``flock``, which the system releases
    however the process ends (the file stays, holding the last holder's pid). A second trainer on the
    same folder gets a one-line OutputError naming the lock and the pid that holds it."""
    import fcntl

    out.mkdir(parents=True, exist_ok=True)
    path = out / LOCK_NAME
    with open(path, "a+", encoding="utf-8") as fh:
        try:
            fcntl.flock(fh, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            fh.seek(0)
            holder = fh.read().strip() or "unknown"
            raise OutputError(path, f"another volsr train (pid {holder}) is training into {out}; "
                              "wait for it to finish or stop it") from None
        fh.seek(0)
        fh.truncate()
        fh.write(f"{os.getpid()}\n")
        fh.flush()
        yield


class EpochSamples(torch.utils.data.Dataset):
    """Wraps a SequenceDataset so that a sampler can name (epoch, index): seeded per epoch in workers too."""

    def __init__(self, dataset: SequenceDataset):
        self.dataset = dataset

    def __len__(self) -> int:
        return len(self.dataset)

    def __getitem__(self, key: tuple[int, int]) -> dict[str, torch.Tensor]:
        epoch, index = key
        self.dataset.set_epoch(epoch)
        return self.dataset[index]


class StepBatches(Sampler):
    """Yields, for steps start..steps-1, this rank's share of the global batch as (epoch, index) keys."""

    def __init__(self, n_samples: int, global_batch: int, seed: int, start: int, steps: int, rank: int = 0,
                 world: int = 1):
        self.n, self.batch, self.seed = n_samples, global_batch, seed
        self.start, self.steps, self.rank, self.world = start, steps, rank, world
        self.per_epoch = max(n_samples // global_batch, 1)

    def __len__(self) -> int:
        return self.steps - self.start

    def __iter__(self) -> Iterator[list[tuple[int, int]]]:
        order, order_epoch = None, -1
        for step in range(self.start, self.steps):
            epoch, position = divmod(step, self.per_epoch)
            if epoch != order_epoch:
                g = torch.Generator().manual_seed(self.seed * 1_000_003 + epoch)
                order, order_epoch = torch.randperm(self.n, generator=g), epoch
            picked = order[(position * self.batch) % self.n:][: self.batch]
            if len(picked) < self.batch:  # fewer samples than a batch: wrap around
                picked = order.repeat(math.ceil(self.batch / self.n))[: self.batch]
            yield [(epoch, int(i)) for i in picked[self.rank::self.world]]


def build_model(config: TrainingConfig) -> SuperResolutionNet:
    return SuperResolutionNet(network_config(config))


def lr_factor(step: int, warmup: int, total: int, min_ratio: float) -> float:
    """Linear warm-up to 1 over ``warmup`` steps, then cosine down to ``min_ratio`` at ``total``."""
    if step < warmup:
        return (step + 1) / warmup
    progress = min((step - warmup) / max(total - warmup, 1), 1.0)
    return min_ratio + (1.0 - min_ratio) * 0.5 * (1.0 + math.cos(math.pi * progress))


class Trainer:
    """``Trainer(config).run()`` trains to ``train.steps``, resuming from ``out/checkpoints/last.pt``."""

    def __init__(self, config: TrainingConfig, progress: bool = True):
        self.config, self.progress = config, progress
        self.world = int(os.environ.get("WORLD_SIZE", "1"))
        self.rank = int(os.environ.get("RANK", "0"))
        self.device = torch.device(f"cuda:{int(os.environ.get('LOCAL_RANK', 0))}" if torch.cuda.is_available() else "cpu")
        if self.world > 1 and not dist.is_initialized():
            dist.init_process_group("nccl" if self.device.type == "cuda" else "gloo")
        if self.device.type == "cuda":
            torch.cuda.set_device(self.device)
        self.out = Path(config.out)
        data = config.data
        # a sample carries the frames of `unroll` steps: N previous frames for the oldest step, plus one per step
        self.unroll = config.train.unroll
        frames = data.previous_frames + self.unroll - 1
        self.taau_network = build_model(config).config if config.model.taau_base else None
        self.train_set = SequenceDataset(data.root, "train", data.scale, frames, data.crop,
                                         data.features, augment=data.augment, seed=config.seed,
                                         hr_frames=self.unroll, taau=self.taau_network)
        self.val_set = SequenceDataset(data.root, "val", data.scale, frames, data.val_crop,
                                       data.features, augment=False, seed=config.seed,
                                       hr_frames=self.unroll, taau=self.taau_network)
        torch.manual_seed(config.seed)
        self.model = build_model(config)
        if config.model.init:
            self._start_from(Path(config.model.init))
        self.model.to(self.device)
        optim = config.optim
        self.optimizer = torch.optim.AdamW(self.model.parameters(), lr=optim.lr, weight_decay=optim.weight_decay)
        steps = config.train.steps
        self.scheduler = torch.optim.lr_scheduler.LambdaLR(
            self.optimizer, lambda s: lr_factor(s, optim.warmup_steps, steps, optim.min_lr_ratio))
        self.amp = config.train.amp and self.device.type == "cuda"
        self.scaler = torch.amp.GradScaler("cuda", enabled=self.amp)
        self.loss = ReconstructionLoss(config.loss.charbonnier_eps, config.loss.ssim_weight)
        self.temporal_weight = config.loss.temporal_weight
        self.step, self.best_psnr = 0, -math.inf
        self.ddp = (torch.nn.parallel.DistributedDataParallel(self.model) if self.world > 1 else self.model)

    def _start_from(self, path: Path) -> None:
        """Fine-tuning: begin at the weights of a model file or checkpoint of the same network."""
        start = load_model(path)
        if start.config != self.model.config:
            raise InputError(path, f"model.init is a different network ({start.config.to_dict()}) "
                                   f"from the config's ({self.model.config.to_dict()})")
        self.model.load_state_dict(start.state_dict())

    # -- state ---------------------------------------------------------------------------------
    def state(self) -> dict[str, Any]:
        return {"model": self.model.state_dict(), "network": self.model.config.to_dict(),
                "optimizer": self.optimizer.state_dict(), "scheduler": self.scheduler.state_dict(),
                "scaler": self.scaler.state_dict(), "step": self.step, "best_psnr": self.best_psnr,
                "rng": {"torch": torch.get_rng_state(), "numpy": np.random.get_state(), "python": random.getstate()},
                "config": self.config.to_dict()}

    def restore(self, path: Path) -> None:
        """The training state of checkpoint ``path``; InputError when it is unreadable or incomplete."""
        state = load_checkpoint(path, trusted=True)
        try:
            self.model.load_state_dict(state["model"])
            self.optimizer.load_state_dict(state["optimizer"])
            self.scheduler.load_state_dict(state["scheduler"])
            self.scaler.load_state_dict(state["scaler"])
            self.step, self.best_psnr = int(state["step"]), float(state["best_psnr"])
            torch.set_rng_state(state["rng"]["torch"])
            np.random.set_state(state["rng"]["numpy"])
            random.setstate(state["rng"]["python"])
        except (KeyError, TypeError, ValueError, RuntimeError) as err:
            raise InputError(path, f"not a complete training checkpoint of this network "
                             f"({type(err).__name__}: {' '.join(str(err).split())[:160]})") from None

    def resume(self) -> None:
        """Restore the newest readable checkpoint in ``out/checkpoints``: ``last.pt``, else the ``step_*.pt``
        files newest first, saying on stderr which one when it is not ``last.pt``. No checkpoint: step 0;
        none readable: a one-line InputError."""
        folder = self.out / "checkpoints"
        last = folder / "last.pt"
        unreadable: list[str] = []
        for path in [last] + sorted(folder.glob("step_*.pt"), reverse=True):
            if not path.is_file():
                continue
            try:
                self.restore(path)
            except InputError as err:
                unreadable.append(str(err))
                continue
            if path != last and self.rank == 0:
                why = "; ".join(unreadable) or f"{last}: missing"
                print(f"volsr train: {why}; resumed from {path.name} (step {self.step}) instead",
                      file=sys.stderr)
            return
        if unreadable:
            raise InputError(folder, f"no readable checkpoint to resume from ({'; '.join(unreadable)}); "
                             "move the folder away to start over")

    # -- loop ----------------------------------------------------------------------------------
    def run(self, until: int | None = None) -> dict[str, Any]:
        """Train from the newest readable checkpoint to ``train.steps`` (or stop after step ``until``,
        checkpointing), holding the run folder's lock (rank 0)."""
        with run_folder_lock(self.out) if self.rank == 0 else contextlib.nullcontext():
            return self._train(until)

    def _train(self, until: int | None) -> dict[str, Any]:
        cfg = self.config.train
        last = self.out / "checkpoints" / "last.pt"
        self.resume()
        if self.rank == 0:
            (self.out / "checkpoints").mkdir(parents=True, exist_ok=True)
            self._trim_log()
        global_batch = cfg.batch_size
        stop = cfg.steps if until is None else min(until, cfg.steps)
        sampler = StepBatches(len(self.train_set), global_batch, self.config.seed, self.step, stop,
                              self.rank, self.world)
        validate_every = cfg.validate_every or sampler.per_epoch
        loader = DataLoader(EpochSamples(self.train_set), batch_sampler=sampler,
                            num_workers=self.config.data.num_workers, persistent_workers=False)
        bar = None
        if self.progress and self.rank == 0:
            from tqdm import tqdm
            bar = tqdm(total=cfg.steps, initial=self.step, desc="train", unit="step")
        started = time.perf_counter()
        self.model.train()
        for batch in loader:
            loss = self.train_step(batch)
            self.step += 1
            row = {"step": self.step, "epoch": (self.step - 1) // sampler.per_epoch, "loss": f"{loss:.6f}",
                   "lr": f"{self.scheduler.get_last_lr()[0]:.3e}", "val_psnr": "", "val_ssim": "",
                   "seconds": f"{time.perf_counter() - started:.1f}"}
            if self.step % validate_every == 0 or self.step == cfg.steps:
                metrics = self.validate()
                row["val_psnr"], row["val_ssim"] = f"{metrics['psnr']:.3f}", f"{metrics['ssim']:.4f}"
                if self.rank == 0 and metrics["psnr"] > self.best_psnr:
                    self.best_psnr = metrics["psnr"]
                    save_checkpoint(self.out / "best.pt", self.model, extra={"step": self.step, **metrics})
            if self.rank == 0:
                self._log(row)
                if self.step % cfg.checkpoint_every == 0 or self.step == stop:
                    save_checkpoint(last, state=self.state())
                    save_checkpoint(self.out / "checkpoints" / f"step_{self.step:07d}.pt", state=self.state())
                if bar is not None:
                    bar.set_postfix(loss=row["loss"], val=row["val_psnr"] or None)
                    bar.update(1)
        if bar is not None:
            bar.close()
        return {"step": self.step, "best_psnr": self.best_psnr}

    def train_step(self, batch: dict[str, torch.Tensor]) -> float:
        targets = batch["hr_sequence" if self.unroll > 1 else "hr"].to(self.device)
        if self.unroll == 1:
            targets = targets[:, None]
        self.optimizer.zero_grad(set_to_none=True)
        with torch.autocast(self.device.type, dtype=torch.float16, enabled=self.amp):
            outputs = self.forward(self.ddp, batch)[::-1]  # index k = frame t-k, as the targets
            loss = sum(self.loss(out, targets[:, k]) for k, out in enumerate(outputs)) / len(outputs)
            if self.temporal_weight and len(outputs) > 1:
                motion = batch["motion"].to(self.device)
                loss = loss + self.temporal_weight * sum(
                    temporal_charbonnier(outputs[k], outputs[k + 1], targets[:, k], targets[:, k + 1],
                                         upsample_motion(motion[:, k], self.model.config.scale), self.loss.eps)
                    for k in range(len(outputs) - 1)) / (len(outputs) - 1)
        self.scaler.scale(loss).backward()
        self.scaler.step(self.optimizer)
        self.scaler.update()
        self.scheduler.step()
        return float(loss.detach())

    def forward(self, model: torch.nn.Module, batch: dict[str, torch.Tensor]) -> list[torch.Tensor]:
        """The outputs for the batch's last ``unroll`` frames, oldest first (the history as
        :mod:`volsr_core.sr.history` picks it: each step's TAAU frame, or the previous output)."""
        cfg = self.model.config
        lr, motion, jitter = (batch[k].to(self.device) for k in ("lr", "motion", "jitter"))
        taau = batch["taau"].to(self.device) if "taau" in batch else None
        return run_unrolled(model, lr, motion, jitter, self.unroll, cfg.previous_frames, history_mode(cfg), taau)

    @torch.no_grad()
    def validate(self) -> dict[str, float]:
        """Mean PSNR/SSIM (scikit-image) on up to ``train.max_val_samples`` validation samples."""
        self.model.eval()
        n = min(len(self.val_set), self.config.train.max_val_samples)
        picks = np.linspace(0, len(self.val_set) - 1, n).round().astype(int) if n else []
        scores = []
        for i in picks:
            item = self.val_set[int(i)]
            out = self.forward(self.model, {k: v[None] for k, v in item.items()})[-1]
            scores.append(psnr_ssim(out[0].float().cpu().numpy(), item["hr"].numpy()))
        self.model.train()
        if not scores:
            return {"psnr": float("nan"), "ssim": float("nan")}
        return {"psnr": float(np.mean([s[0] for s in scores])), "ssim": float(np.mean([s[1] for s in scores]))}

    # -- CSV log -------------------------------------------------------------------------------
    def _log(self, row: dict[str, Any]) -> None:
        path = self.out / "log.csv"
        new = not path.exists()
        with path.open("a", newline="") as fh:
            writer = csv.DictWriter(fh, LOG_FIELDS)
            if new:
                writer.writeheader()
            writer.writerow(row)

    def _trim_log(self) -> None:
        """Drop log rows past the resumed step (they belong to a run that was cut off)."""
        path = self.out / "log.csv"
        if not path.exists():
            return
        with path.open(newline="") as fh:
            rows = [r for r in csv.DictReader(fh) if int(r["step"]) <= self.step]
        with atomic_write(path, "w", newline="") as fh:
            writer = csv.DictWriter(fh, LOG_FIELDS)
            writer.writeheader()
            writer.writerows(rows)
