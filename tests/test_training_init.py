"""``init = WEIGHTS`` in a training config: the first stage starts from exported weights (a trained model)
instead of a random initialisation; bad files are one error naming the file before any work."""

from __future__ import annotations

from pathlib import Path

import pytest
import torch
from test_training import plane_training_root, tiny_config

from lfbench.training import checkpoint as ckpt
from lfbench.training.config import TrainConfig
from lfbench.utils.errors import DataError

pytestmark = pytest.mark.usefixtures("one_torch_thread")


@pytest.fixture(scope="module")
def data_root(tmp_path_factory) -> Path:
    return plane_training_root(tmp_path_factory.mktemp("hci_init"))


def _config(data_root: Path, init: str | None, lr: float = 1e-3, steps: int = 2) -> TrainConfig:
    d = tiny_config(data_root).to_dict()
    d["stages"] = [{"name": "l1", "loss": "l1", "lr": lr, "steps": steps}]
    d["validation"] = {"every": 0, "max_size": 0}
    if init is not None:
        d["init"] = init
    return TrainConfig.from_dict(d)


def _weights(tmp_path: Path, width: int = 4, seed: int = 11) -> Path:
    from lfbench_methods.subfocal.network import SubFocalNet

    torch.manual_seed(seed)
    net = SubFocalNet(width=width)
    with torch.no_grad():
        for p in net.parameters():
            p.add_(0.01)  # not what any seed's fresh initialisation gives
    path = tmp_path / f"init_w{width}.pt"
    ckpt.export_weights(path, net, {"note": "test"})
    return path


def test_init_key_round_trips_and_is_left_out_when_absent(data_root, tmp_path):
    assert "init" not in _config(data_root, None).to_dict()  # fingerprints of older configs unchanged
    cfg = _config(data_root, "some/weights.pt")
    assert cfg.init == "some/weights.pt" and cfg.to_dict()["init"] == "some/weights.pt"
    assert TrainConfig.from_dict(cfg.to_dict()) == cfg


def test_first_stage_starts_from_the_init_weights(data_root, tmp_path):
    from lfbench.training.loop import train

    init = _weights(tmp_path)
    start = ckpt.load(init)["state_dict"]
    # A learning rate of 1e-12 leaves the weights where they started: the final parameters are the init's.
    out = tmp_path / "run"
    result = train(_config(data_root, str(init), lr=1e-12), out, progress=False)
    final = ckpt.load(out / "final.pt")
    params = [n for n, t in final["state_dict"].items() if "running" not in n and "num_batches" not in n]
    for name in params:
        torch.testing.assert_close(final["state_dict"][name], start[name], rtol=0, atol=1e-9, msg=name)
    assert final["training"]["init"] == {"path": str(init), "sha256": ckpt.state_sha256(start)}
    assert result["steps"] == 2
    # Without init the same config starts from the seed's initialisation, far from those weights.
    out2 = tmp_path / "fresh"
    train(_config(data_root, None, lr=1e-12), out2, progress=False)
    fresh = ckpt.load(out2 / "final.pt")["state_dict"]
    assert max(float((fresh[n] - start[n]).abs().max()) for n in params) > 5e-3


def test_missing_or_unfit_init_weights_fail_before_any_work(data_root, tmp_path):
    from lfbench.training.loop import train

    out = tmp_path / "never"
    with pytest.raises(DataError, match="file not found") as exc:
        train(_config(data_root, str(tmp_path / "absent.pt")), out, progress=False)
    assert "absent.pt" in str(exc.value)
    assert not (out / "metrics.jsonl").exists() and not (out / "data").exists()  # nothing written but the lock
    wide = _weights(tmp_path, width=6)  # the config builds width 4
    with pytest.raises(DataError, match="init weights: weights do not fit the network") as exc:
        train(_config(data_root, str(wide)), tmp_path / "unfit", progress=False)
    assert "init_w6.pt" in str(exc.value)
    bad = tmp_path / "not_weights.pt"
    torch.save({"format": "something", "values": [1, 2]}, bad)
    with pytest.raises(DataError, match="not an exported weights file"):
        train(_config(data_root, str(bad)), tmp_path / "bad", progress=False)
