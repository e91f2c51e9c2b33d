"""The ``cuda`` backend of ``aa_rnn``: the network runs with PyTorch on a CUDA GPU.

It needs ``torch.cuda`` (a CUDA build of PyTorch and a GPU), not ``numba.cuda``: Numba's CUDA
simulator does not make this backend available.
"""

from __future__ import annotations


def device():
    """The PyTorch device of this backend; raises ``RuntimeError`` without ``torch.cuda``."""
    import torch

    if not torch.cuda.is_available():
        raise RuntimeError("aa_rnn: backend 'cuda' runs PyTorch on a CUDA GPU, and torch.cuda is not available here")
    return torch.device("cuda")
