import pytest
import torch

from pipeline.models.exports import read_weights_file


class Gadget:
    """Any class of ours: unpickling an instance imports and runs code from its module."""


def test_reads_a_saved_dict_of_tensors(tmp_path):
    path = tmp_path / "ok.pt"
    torch.save({"config": {"width": 4}, "state_dict": {"w": torch.ones(2)}}, path)
    payload = read_weights_file(path, "a test export")
    assert payload["config"] == {"width": 4} and torch.equal(payload["state_dict"]["w"], torch.ones(2))


def test_refuses_what_is_not_a_weights_dict(tmp_path):
    with pytest.raises(FileNotFoundError, match=r"file not found \(expected a test export\)"):
        read_weights_file(tmp_path / "missing.pt", "a test export")
    text = tmp_path / "text.pt"
    text.write_text("hello")
    with pytest.raises(ValueError, match=r"text.pt: not a test export \(not a file written by torch.save\)"):
        read_weights_file(text, "a test export")
    tensor = tmp_path / "tensor.pt"
    torch.save(torch.zeros(3), tensor)
    with pytest.raises(ValueError, match="it holds a Tensor, not a dict"):
        read_weights_file(tensor, "a test export")
    code = tmp_path / "code.pt"
    torch.save({"gadget": Gadget()}, code)
    with pytest.raises(ValueError, match="refused because loading them would run code"):
        read_weights_file(code, "a test export")
