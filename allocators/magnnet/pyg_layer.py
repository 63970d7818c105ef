"""MAGNNET's graph convolution written with PyTorch Geometric, for comparison with our dense form.

:class:`~allocators.magnnet.model.HeteroGraphConv` runs the paper's layer on many small graphs
of equal size as batched matrix products. This module builds the same layer from PyG's parts
(``HeteroConv`` over a ``HeteroData`` batch: ``SAGEConv`` with mean aggregation on the
agent-agent communication edges, a mean-aggregating ``MessagePassing`` over the task->agent
edges with the edge features, a linear update of the task nodes), so that:

* a test shows the two compute the same function with the same weights;
* ``benchmarks/gnn_layers.py`` measures which is faster for training, which is why the models
  use the dense form.

Needs ``torch_geometric`` (the ``test`` and ``bench`` extras); nothing at run time imports it.
"""

from __future__ import annotations

import warnings

import torch
from torch import nn
from torch_geometric.data import Batch, HeteroData
from torch_geometric.nn import HeteroConv, MessagePassing, SAGEConv

from allocators.magnnet.model import HeteroGraphConv


class TaskToAgent(MessagePassing):
    """``mean_j W [g_j || e_ij]`` over the task->agent edges (every task, so ``sum / M``)."""

    def __init__(self, task_in: int, edge_in: int, out: int) -> None:
        super().__init__(aggr="mean")
        self.lin = nn.Linear(task_in + edge_in, out, bias=False)

    def forward(self, x, edge_index, edge_attr):
        src, dst = x
        return self.propagate(edge_index, x=(src, dst), edge_attr=edge_attr,
                              size=(src.shape[0], dst.shape[0]))

    def message(self, x_j, edge_attr):
        return self.lin(torch.cat([x_j, edge_attr], -1))


class PygHeteroGraphConv(nn.Module):
    """The layer of :class:`~allocators.magnnet.model.HeteroGraphConv`, on a PyG batch."""

    def __init__(self, agent_in: int, task_in: int, edge_in: int, out: int) -> None:
        super().__init__()
        with warnings.catch_warnings():
            # task nodes receive no messages by design (the paper's layer updates them alone)
            warnings.filterwarnings("ignore", message="There exist node types")
            self.conv = HeteroConv({
                ("agent", "talks", "agent"): SAGEConv(agent_in, out, aggr="mean"),
                ("task", "to", "agent"): TaskToAgent(task_in, edge_in, out),
            }, aggr="sum")
        self.task_self = nn.Linear(task_in, out)

    @classmethod
    def from_dense(cls, dense: HeteroGraphConv) -> PygHeteroGraphConv:
        """A copy of ``dense`` with the same weights."""
        agent_in = dense.self_lin.in_features
        task_in = dense.task_self.in_features
        edge_in = dense.task_lin.in_features - task_in
        out = dense.self_lin.out_features
        layer = cls(agent_in, task_in, edge_in, out)
        sage = layer.conv.convs[("agent", "talks", "agent")]
        with torch.no_grad():
            sage.lin_l.weight.copy_(dense.nb_lin.weight)  # on the neighbours' mean
            sage.lin_l.bias.copy_(dense.self_lin.bias)
            sage.lin_r.weight.copy_(dense.self_lin.weight)  # on the node itself
            layer.conv.convs[("task", "to", "agent")].lin.weight.copy_(dense.task_lin.weight)
            layer.task_self.load_state_dict(dense.task_self.state_dict())
        return layer

    def forward(self, data: HeteroData):
        out = self.conv(data.x_dict, data.edge_index_dict,
                        edge_attr_dict={("task", "to", "agent"):
                                        data["task", "to", "agent"].edge_attr})
        return torch.relu(out["agent"]), torch.relu(self.task_self(data["task"].x))


def to_pyg(h: torch.Tensor, g: torch.Tensor, e: torch.Tensor, adj: torch.Tensor) -> Batch:
    """The dense batch ``agents (B, N, F)``, ``tasks (B, M, G)``, ``edges (B, N, M, E)``,
    ``adjacency (B, N, N)`` as one PyG batch of ``B`` heterogeneous graphs."""
    graphs = []
    n, m = h.shape[1], g.shape[1]
    tj, ai = torch.meshgrid(torch.arange(m), torch.arange(n), indexing="xy")
    task_edges = torch.stack([tj.reshape(-1), ai.reshape(-1)])  # task j -> agent i, (i, j)
    for b in range(h.shape[0]):
        d = HeteroData()
        d["agent"].x = h[b]
        d["task"].x = g[b]
        src, dst = adj[b].T.nonzero(as_tuple=True)  # message k -> i where adj[i, k]
        d["agent", "talks", "agent"].edge_index = torch.stack([src, dst])
        d["task", "to", "agent"].edge_index = task_edges
        d["task", "to", "agent"].edge_attr = e[b].reshape(n * m, -1)
        graphs.append(d)
    return Batch.from_data_list(graphs)
