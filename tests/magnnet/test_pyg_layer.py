"""Our dense graph convolution computes the same function as its PyTorch Geometric version."""

from __future__ import annotations

import pytest

torch = pytest.importorskip("torch")
pytest.importorskip("torch_geometric")

from allocators.magnnet.model import HeteroGraphConv  # noqa: E402
from allocators.magnnet.pyg_layer import PygHeteroGraphConv, to_pyg  # noqa: E402


@pytest.mark.parametrize("seed", [0, 1])
def test_dense_layer_equals_pyg(seed):
    torch.manual_seed(seed)
    b, n, m = 3, 5, 4
    dense = HeteroGraphConv(7, 4, 2, 6)
    pyg = PygHeteroGraphConv.from_dense(dense)
    h, g, e = torch.randn(b, n, 7), torch.randn(b, m, 4), torch.randn(b, n, m, 2)
    adj = (torch.rand(b, n, n) < 0.4).float()
    adj = ((adj + adj.transpose(1, 2)) > 0).float()
    adj[:, torch.arange(n), torch.arange(n)] = 1.0  # the diagonal, as the observations have it
    want_h, want_g = dense(h, g, e, adj)
    got_h, got_g = pyg(to_pyg(h, g, e, adj))
    torch.testing.assert_close(got_h.reshape(b, n, -1), want_h, rtol=1e-5, atol=1e-5)
    torch.testing.assert_close(got_g.reshape(b, m, -1), want_g, rtol=1e-5, atol=1e-5)
