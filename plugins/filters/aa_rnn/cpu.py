"""The ``cpu`` backend of ``aa_rnn``: the network runs with PyTorch on the CPU."""

from __future__ import annotations


def device():
    """The PyTorch device of this backend."""
    import torch

    return torch.device("cpu")
