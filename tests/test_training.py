"""Training: a tiny model overfits a tiny sequence, resume is exact, torchrun (gloo, 2 CPUs) runs.

The dataset (conftest's ``tiny_sequences``): 3 phantom videos of 3 frames, one each for train,
val and test, so with 2 previous frames the training split is one sample: the sequence the
model overfits.
"""
from __future__ import annotations

import csv
import os
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

torch = pytest.importorskip("torch")

from volsr_core.errors import InputError  # noqa: E402
from volsr_core.sr.checkpoint import load_checkpoint  # noqa: E402
from volsr_core.sr.config import LossSection, TrainingConfig, load_training_config, network_config  # noqa: E402
from volsr_core.sr.network import SuperResolutionNet  # noqa: E402
from volsr_core.sr.training import Trainer  # noqa: E402

def write_config(folder: Path, dataset: Path, recurrent: bool = False, **train) -> Path:
    """A tiny config; ``recurrent`` trains the recurrent network (N = 0) unrolled over all 3 frames."""
    config = {
        "seed": 1, "out": str(folder / "run"),
        "data": {"root": str(dataset), "scale": 4, "previous_frames": 0 if recurrent else 2, "crop": 32},
        "model": {"variant": "S", "widths": [8, 12], "recurrent": recurrent},
        "optim": {"lr": 3e-3, "warmup_steps": 5},
        "train": {"steps": 8, "batch_size": 2, "checkpoint_every": 4, **({"unroll": 3} if recurrent else {}), **train},
    }
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / "train.yaml"
    path.write_text(yaml.safe_dump(config))
    return path


def losses(run: Path) -> list[float]:
    with (run / "log.csv").open() as fh:
        return [float(r["loss"]) for r in csv.DictReader(fh)]


def test_a_tiny_model_overfits_a_tiny_sequence(tiny_sequences, tmp_path):
    path = write_config(tmp_path, tiny_sequences, steps=150, checkpoint_every=150, validate_every=150)
    config = load_training_config(path).updated({"data": {"augment": False}, "model": {"widths": [16, 24]},
                                                 "optim": {"weight_decay": 0.0, "warmup_steps": 1, "min_lr_ratio": 1.0}})
    Trainer(config, progress=False).run()
    loss = losses(tmp_path / "run")
    first, last = sum(loss[:5]) / 5, sum(loss[-5:]) / 5
    print(f"loss {first:.4f} -> {last:.4f}")
    assert last <= first / 10


@pytest.mark.parametrize("recurrent", [False, True])
def test_resume_gives_the_weights_of_an_uninterrupted_run(tiny_sequences, tmp_path, recurrent):
    straight = load_training_config(write_config(tmp_path / "a", tiny_sequences, recurrent))
    Trainer(straight, progress=False).run()
    interrupted = load_training_config(write_config(tmp_path / "b", tiny_sequences, recurrent))
    Trainer(interrupted, progress=False).run(until=4)
    state = load_checkpoint(tmp_path / "b" / "run" / "checkpoints" / "last.pt", trusted=True)
    assert state["step"] == 4
    assert isinstance(state["config"], dict) and TrainingConfig.from_dict(state["config"]) == interrupted
    Trainer(interrupted, progress=False).run()  # a new process would do the same: resumes from last.pt
    a = load_checkpoint(tmp_path / "a" / "run" / "checkpoints" / "last.pt", trusted=True)["model"]
    b = load_checkpoint(tmp_path / "b" / "run" / "checkpoints" / "last.pt", trusted=True)["model"]
    for name in a:
        assert torch.equal(a[name], b[name]), name
    assert losses(tmp_path / "a" / "run") == losses(tmp_path / "b" / "run")


def test_torchrun_two_cpu_processes(tiny_sequences, tmp_path):
    config = write_config(tmp_path, tiny_sequences, steps=4, checkpoint_every=2)
    env = {**os.environ, "OMP_NUM_THREADS": "1"}
    result = subprocess.run([sys.executable, "-m", "torch.distributed.run", "--standalone", "--nproc_per_node=2",
                             "-m", "volsr_core.cli", "train", str(config)], capture_output=True, text=True,
                            env=env, timeout=300)
    assert result.returncode == 0, result.stdout[-3000:] + result.stderr[-3000:]
    state = load_checkpoint(tmp_path / "run" / "checkpoints" / "last.pt", trusted=True)
    assert state["step"] == 4
    assert len(losses(tmp_path / "run")) == 4


def test_a_taau_based_network_trains_unrolled_with_the_temporal_loss(tiny_sequences, tmp_path):
    path = write_config(tmp_path, tiny_sequences, steps=6, unroll=2, validate_every=6)
    config = load_training_config(path).updated({"data": {"previous_frames": 0}, "model": {"taau_base": True},
                                                 "loss": {"temporal_weight": 0.5}})
    result = Trainer(config, progress=False).run()
    assert result["step"] == 6 and torch.isfinite(torch.tensor(losses(tmp_path / "run"))).all()
    assert result["best_psnr"] > 10


def test_a_u_net_trains_on_the_layered_taau_of_the_datasets_depth_slabs(tiny_layered_sequences, tmp_path):
    """``model: {taau_slabs: 2}`` on a U-Net: the loader's history is the layered TAAU's estimate of the dataset's
    depth slabs (three channels, no side outputs), the network trains on it, and the checkpoint keeps the setting."""
    from volsr_core.sr.checkpoint import load_model

    path = write_config(tmp_path, tiny_layered_sequences, steps=4, unroll=2, validate_every=4)
    config = load_training_config(path).updated({"data": {"previous_frames": 0},
                                                 "model": {"taau_base": True, "taau_slabs": 2}})
    result = Trainer(config, progress=False).run()
    assert result["step"] == 4 and torch.isfinite(torch.tensor(losses(tmp_path / "run"))).all()
    model = load_model(tmp_path / "run" / "best.pt")
    assert (model.config.taau_slabs, model.config.history_channels, bool(model.config.widths)) == (2, 3, True)


def test_model_init_starts_fine_tuning_from_given_weights(tiny_sequences, tmp_path):
    first = load_training_config(write_config(tmp_path / "a", tiny_sequences, steps=4))
    Trainer(first, progress=False).run()
    start = tmp_path / "a" / "run" / "checkpoints" / "last.pt"
    tuned = load_training_config(write_config(tmp_path / "b", tiny_sequences, steps=4))
    tuned = tuned.updated({"model": {"init": str(start)}})
    trainer = Trainer(tuned, progress=False)
    expected = load_checkpoint(start, trusted=True)["model"]
    for name, value in trainer.model.state_dict().items():
        assert torch.equal(value, expected[name]), name
    other = load_training_config(write_config(tmp_path / "c", tiny_sequences, steps=4))
    other = other.updated({"model": {"widths": [8, 16], "init": str(start)}})
    with pytest.raises(InputError, match="different network"):
        Trainer(other, progress=False)


def test_defaults_fill_what_the_file_leaves_out_and_paths_resolve_against_its_folder(tmp_path):
    path = tmp_path / "configs" / "train.yaml"
    path.parent.mkdir()
    path.write_text("data: {root: ../data}\ntrain: {steps: 5}\nloss:\n")
    config = load_training_config(path)
    assert config.data.root == str((tmp_path / "data").resolve())
    assert config.out == str((path.parent / "runs" / "default").resolve())
    assert config.train.steps == 5 and config.train.batch_size == 8 and config.train.validate_every is None
    assert config.data.features == ("color", "depth", "max_rgba") and config.data.crop == 96
    assert config.model.variant == "S" and config.model.init is None and config.optim.lr == 1e-3
    assert config.loss == LossSection() and config.seed == 0


def test_the_model_section_sizes_each_block_of_the_variant(tmp_path):
    path = tmp_path / "train.yaml"
    path.write_text("data: {root: data, scale: 2, previous_frames: 0}\n"
                    "model: {variant: S, taau_base: true, widths: [16, 24], feature_width: 8, reweight_width: 12}\n")
    net = SuperResolutionNet(network_config(load_training_config(path)))
    assert (net.config.widths, net.config.fold) == ((16, 24), 2)
    assert net.features.conv1.out_channels == 8 and net.reweight.first.out_channels == 12
    assert net.reconstruct.first.out_channels == 16


@pytest.mark.parametrize("text, message", [
    ("data: {root: x}\nsede: 1", "sede: unknown key (allowed: seed, out, data, model, optim, train, loss)"),
    ("data: {root: x, rot: y}", "data.rot: unknown key (allowed: root, scale, previous_frames, crop, features,"),
    ("data: {root: x}\nmodel: {varient: M}", "model.varient: unknown key (allowed: variant, fold, widths,"),
    ("data: {root: x}\noptim: {learning_rate: 1}", "optim.learning_rate: unknown key (allowed: lr, weight_decay,"),
    ("data: {root: x}\ntrain: {stepz: 10}", "train.stepz: unknown key (allowed: steps, batch_size, unroll,"),
    ("data: {root: x}\nloss: {l1: 1}", "loss.l1: unknown key (allowed: charbonnier_eps, ssim_weight,"),
    ("data: {root: x}\ntrain: {steps: '10'}", "train.steps: expected an integer, got str '10'"),
    ("data: {root: x}\ntrain: {batch_size: 0}", "train.batch_size: must be at least 1, got 0"),
    ("data: {root: x}\ntrain: {amp: 1}", "train.amp: expected true or false, got int 1"),
    ("data: {root: x, features: color}", "data.features: expected a list, got str 'color'"),
    ("data: {root: x}\noptim: {lr: fast}", "optim.lr: expected a number, got str 'fast'"),
    ("data: {root: x}\nmodel: {widths: [8, 12.5]}", "model.widths[1]: expected an integer, got float 12.5"),
    ("data: {root: x}\nloss: [1]", "loss: expected a mapping, got list [1]"),
    ("data: {root: x}\nmodel: {variant: XS, base_kernel: 4}", "model: base_kernel must be 0 or odd, got 4"),
    ("data: {root: x}\nmodel: {variant: XS, base_orientations: 3}", "model: base_orientations must be 1, or 2 with"),
    ("data: {root: x}\nmodel: {variant: S, taau_base: true, taau_aux: true, taau_slabs: 2}",
     "model: taau_slabs puts a TAAU-based network"),
    ("data: {root: x}\nmodel: {reweight_width: 0}", "model: reweight_width: channels must be at least 1, got 0"),
    ("data: {root: x}\nmodel: {widths: [16, 0]}", "model: widths: channels must be at least 1, got (16, 0)"),
    ("seed: 1", "data.root: missing (the dataset folder made by `volsr dataset`)"),
    ("", "(top level): expected a mapping, got nothing"),
    ("data: {root: x", "not valid YAML at line 1"),
])
def test_a_bad_training_config_is_a_one_line_error_naming_the_key(tmp_path, text, message):
    path = tmp_path / "train.yaml"
    path.write_text(text)
    with pytest.raises(InputError) as caught:
        load_training_config(path)
    assert str(caught.value).startswith(f"{path}: ") and "\n" not in str(caught.value)
    assert message in str(caught.value)


def test_changes_to_a_config_are_checked_as_the_file_is(tmp_path):
    path = tmp_path / "train.yaml"
    path.write_text("data: {root: x}")
    config = load_training_config(path)
    assert config.updated({"train": {"steps": 3}}).train.steps == 3
    with pytest.raises(InputError, match=r"config changes: train\.stepz: unknown key \(allowed: steps,"):
        config.updated({"train": {"stepz": 3}})
    with pytest.raises(InputError, match="config changes: data.scale: expected an integer"):
        config.updated({"data": {"scale": "4"}})


def test_one_trainer_per_run_folder(tmp_path):
    from volsr_core.errors import OutputError
    from volsr_core.sr.training import run_folder_lock

    with run_folder_lock(tmp_path / "run"):
        assert (tmp_path / "run" / "train.lock").read_text() == f"{os.getpid()}\n"
        with pytest.raises(OutputError, match=rf"train.lock: another volsr train \(pid {os.getpid()}\) is training"):
            with run_folder_lock(tmp_path / "run"):
                pass
    with run_folder_lock(tmp_path / "run"):  # released when the first one ended
        pass
