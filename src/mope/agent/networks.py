"""Networks: the Q-networks (the paper's conditioned one and mope's convex head) and the preference discriminator.

* :class:`QNetwork` -- Q(s, a, omega), paper sec. 4: the state and the preference are concatenated and go
  through fully connected hidden layers (the paper: {64, 128, 128, 64}); the output has one head per objective,
  i.e. ``|A| x m`` values (Abels et al. 2019's conditioned network). The ``paper`` preset's network.
* :class:`ConvexQNetwork` -- mope's default (``q_head: convex``): C return vectors per action from the state
  alone; Q(s, a, omega) is the one omega prefers (see its docstring and docs/design.md).
* :class:`Discriminator` -- q_phi(omega | s), paper eq. 6: three fully connected layers that output a
  categorical distribution over the N_I preference cells of preference exploration (see docs/design.md).
* :class:`ObsEncoder` -- turns a Gymnasium observation into a flat float vector: a bounded ``Box`` is scaled
  to [0, 1] or, for a small integer ``Box`` (``auto``, the default, or ``onehot``), each coordinate is one-hot
  encoded; an unbounded ``Box`` is flattened, a ``Discrete`` one is one-hot encoded.
"""

from __future__ import annotations

from collections.abc import Sequence

import gymnasium as gym
import numpy as np
import torch
from torch import nn

from mope.config import ENCODINGS
from mope.errors import EnvironmentError_

#: "joint" one-hot encodes the whole cell of an integer Box; it refuses a Box with more cells than this.
JOINT_MAX = 65_536
#: "auto" one-hot encodes an integer Box whose coordinates take at most this many values in all.
AUTO_ONEHOT_MAX = 1024


def resolve_encoding(space: gym.Space, encoding: str) -> str:
    """``auto`` -> ``onehot`` for a small integer ``Box`` (at most AUTO_ONEHOT_MAX values over all coordinates),
    else ``scale``; other encodings are returned as they are."""
    if encoding != "auto":
        return encoding
    if isinstance(space, gym.spaces.Box) and np.issubdtype(space.dtype, np.integer) \
            and np.all(np.isfinite(space.low)) and np.all(np.isfinite(space.high)):
        sizes = np.asarray(space.high, dtype=np.int64) - np.asarray(space.low, dtype=np.int64) + 1
        if sizes.sum() <= AUTO_ONEHOT_MAX:
            return "onehot"
    return "scale"


class ObsEncoder(nn.Module):
    """Flat float features of an observation from a ``Box`` or ``Discrete`` space.

    ``encoding="scale"`` (default) scales a bounded ``Box`` to [0, 1]; ``"onehot"`` one-hot encodes each
    coordinate of an integer ``Box`` with finite bounds (e.g. DST's (row, col) becomes 12 + 12 indicators);
    ``"joint"`` one-hot encodes the whole cell (12 x 12 indicators: no features shared between states).
    A ``Discrete`` space is always one-hot encoded.
    """

    def __init__(self, space: gym.Space, encoding: str = "scale") -> None:
        super().__init__()
        if encoding not in ENCODINGS:
            raise EnvironmentError_(f"obs_encoding '{encoding}' is unknown; choose one of {', '.join(ENCODINGS)}")
        encoding = resolve_encoding(space, encoding)
        if encoding not in ENCODINGS:
            raise EnvironmentError_(f"obs_encoding '{encoding}' is unknown; choose one of {', '.join(ENCODINGS)}")
        if (encoding in ("onehot", "joint") and isinstance(space, gym.spaces.Box)
                and not np.issubdtype(space.dtype, np.integer)):
            raise EnvironmentError_(f"obs_encoding '{encoding}' needs an integer Box observation, got {space}")
        if encoding in ("onehot", "joint") and isinstance(space, gym.spaces.Box):
            self.kind = "box_onehot" if encoding == "onehot" else "box_joint"
            low = np.asarray(space.low, dtype=np.int64).reshape(-1)
            high = np.asarray(space.high, dtype=np.int64).reshape(-1)
            sizes = high - low + 1
            self.sizes = [int(x) for x in sizes]
            self.out_dim = int(sizes.sum()) if encoding == "onehot" else int(np.prod(sizes))
            if encoding == "joint" and self.out_dim > JOINT_MAX:
                raise EnvironmentError_(f"obs_encoding 'joint' would need {self.out_dim} inputs for {space} (at "
                                        f"most {JOINT_MAX}); use 'onehot' or 'scale'")
            self.register_buffer("low", torch.as_tensor(low, dtype=torch.int64))
            self.register_buffer("scale", torch.as_tensor(sizes, dtype=torch.int64))
            strides = np.concatenate([np.cumprod(sizes[::-1])[::-1][1:], [1]]) if sizes.size else sizes
            self.register_buffer("strides", torch.as_tensor(strides, dtype=torch.int64), persistent=False)
            # where each coordinate's indicators start in the "onehot" features (12 + 12 for DST: 0 and 12)
            offsets = np.concatenate([[0], np.cumsum(sizes)[:-1]]) if sizes.size else sizes
            self.register_buffer("offsets", torch.as_tensor(offsets, dtype=torch.int64), persistent=False)
        elif isinstance(space, gym.spaces.Discrete):
            self.kind = "discrete"
            self.n = int(space.n)
            self.start = int(space.start)
            self.out_dim = self.n
            self.register_buffer("low", torch.zeros(1))
            self.register_buffer("scale", torch.ones(1))
        elif isinstance(space, gym.spaces.Box):
            self.kind = "box"
            low = np.asarray(space.low, dtype=np.float64).reshape(-1)
            high = np.asarray(space.high, dtype=np.float64).reshape(-1)
            bounded = np.isfinite(low) & np.isfinite(high) & (high > low)
            scale = np.where(bounded, high - low, 1.0)
            low = np.where(bounded, low, 0.0)
            self.out_dim = int(low.size)
            self.register_buffer("low", torch.as_tensor(low, dtype=torch.float32))
            self.register_buffer("scale", torch.as_tensor(scale, dtype=torch.float32))
        else:
            raise EnvironmentError_(
                f"observation space {space} is not supported; mope needs a Box or Discrete observation "
                "(wrap others with gymnasium.wrappers.FlattenObservation)"
            )

    def forward(self, obs: torch.Tensor) -> torch.Tensor:
        """Encode a batch of raw observations ``(B, ...)`` into ``(B, out_dim)`` floats."""
        if self.kind == "discrete":
            return nn.functional.one_hot(obs.long().reshape(-1) - self.start, self.n).float()
        if self.kind in ("box_onehot", "box_joint"):
            idx = (obs.reshape(obs.shape[0], -1).long() - self.low).clamp_min(0)
            idx = torch.minimum(idx, self.scale - 1)
            # the indicators written straight into zeros: the same floats as one_hot per coordinate and cat, in
            # 3 ops instead of 3 per coordinate (one_hot also checks its input's range: 2 more reductions each)
            flat = (idx * self.strides).sum(1, keepdim=True) if self.kind == "box_joint" else idx + self.offsets
            return torch.zeros(len(idx), self.out_dim, device=idx.device).scatter_(1, flat, 1.0)
        return (obs.reshape(obs.shape[0], -1).float() - self.low) / self.scale


def mlp(in_dim: int, hidden: Sequence[int], out_dim: int, layer_norm: bool = False) -> nn.Sequential:
    """Fully connected ReLU network ``in_dim -> hidden... -> out_dim``; with ``layer_norm``, each hidden layer is
    normalised before its ReLU (Ba et al. 2016), which bounds the output for any input by the last layer's weights
    (Ball et al. 2023, RLPD: against the overestimation of rarely seen states)."""
    layers: list[nn.Module] = []
    d = in_dim
    for h in hidden:
        layers += [nn.Linear(d, h)] + ([nn.LayerNorm(h)] if layer_norm else []) + [nn.ReLU(inplace=True)]
        d = h
    layers.append(nn.Linear(d, out_dim))
    return nn.Sequential(*layers)


class QNetwork(nn.Module):
    """Preference-conditioned multi-objective Q-network Q(s, a, omega) with one head per objective.

    Args:
        obs_space: The environment's observation space.
        n_actions: |A|.
        n_objectives: m.
        hidden: Hidden layer widths; the paper uses (64, 128, 128, 64).
    """

    def __init__(self, obs_space: gym.Space, n_actions: int, n_objectives: int,
                 hidden: Sequence[int] = (64, 128, 128, 64), obs_encoding: str = "scale", layer_norm: bool = False
                 ) -> None:
        super().__init__()
        self.encoder = ObsEncoder(obs_space, obs_encoding)
        self.n_actions = n_actions
        self.n_objectives = n_objectives
        self.net = mlp(self.encoder.out_dim + n_objectives, hidden, n_actions * n_objectives, layer_norm)

    def forward(self, obs: torch.Tensor, pref: torch.Tensor) -> torch.Tensor:
        """Q-values for all actions.

        Args:
            obs: ``(R, ...)`` raw observations.
            pref: ``(R, m)`` preferences.

        Returns:
            ``(R, |A|, m)`` vector Q-values.
        """
        x = torch.cat([self.encoder(obs), pref], dim=1)
        return self.net(x).view(-1, self.n_actions, self.n_objectives)

    def forward_features(self, feats: torch.Tensor, pref: torch.Tensor) -> torch.Tensor:
        """Same as :meth:`forward` for already encoded observations (lets a batch encode once)."""
        return self.net(torch.cat([feats, pref], dim=1)).view(-1, self.n_actions, self.n_objectives)

    def greedy(self, obs: torch.Tensor, pref: torch.Tensor) -> torch.Tensor:
        """``(R,)`` greedy actions ``argmax_a w^T Q(s, a, w)`` of ``R`` observations, each under its own ``(R, m)``."""
        return torch.einsum("bm,bam->ba", pref, self(obs, pref)).argmax(dim=1)

    def forward_prefs(self, obs: torch.Tensor, prefs: torch.Tensor) -> torch.Tensor:
        """Q-values of each observation under several preferences, in one pass of ``B * K`` rows.

        Args:
            obs: ``(B, ...)`` raw observations.
            prefs: ``(B, K, m)`` preferences, K per observation.

        Returns:
            ``(B, K, |A|, m)`` vector Q-values.
        """
        b, k, m = prefs.shape
        feats = self.encoder(obs)
        rows = feats.unsqueeze(1).expand(b, k, feats.shape[1]).reshape(b * k, -1)
        return self.forward_features(rows, prefs.reshape(b * k, m)).view(b, k, self.n_actions, m)


class ConvexQNetwork(nn.Module):
    """Q(s, a, omega) as the upper envelope of C learned return vectors per action (not in the paper).

    For every state the network outputs C vectors ``v_c(s, a)`` in R^m per action (it does not see omega). Under a
    preference omega, action a's Q-vector is the component that omega prefers::

        c*(s, a, omega) = argmax_c omega^T v_c(s, a)        Q(s, a, omega) = v_{c*}(s, a)

    so ``omega^T Q(s, a, omega) = max_c omega^T v_c(s, a)`` is convex and piecewise linear in omega, exactly the
    shape of the true ``omega^T Q*(s, a, omega)`` for linear utilities (the maximum over the policies' value
    vectors). A conditioned network has to fit the jumps of ``Q*(s, a, .)`` at the preferences where the best
    continuation changes, and smooths them; here they are exact, and only the vectors have to be learned: one
    constant target per component. With C at least the number of convex-coverage-set points reachable from
    (s, a), the envelope max of eq. 4 over *every* preference is the max over components. The component of a
    target is trained by :func:`mope.agent.losses.component_loss` as well as through ``Q``.

    With ``n_critics`` H > 1 the network has H such heads on one trunk, each trained on the same targets, and
    ``Q(s, a, omega)`` is the head with the lowest ``omega^T Q_h(s, a, omega)`` (:meth:`pessimistic`): Maxmin
    Q-learning (Lan et al. 2020). The max over actions and components in the target is then taken over
    pessimistic values, which curbs the upward bias that a max over many noisy vectors feeds back through
    rarely visited states.

    Args:
        obs_space: The environment's observation space.
        n_actions: |A|.
        n_objectives: m.
        hidden: Hidden layer widths.
        obs_encoding: See :class:`ObsEncoder`.
        n_components: C, vectors per action.
        n_critics: H, heads whose minimum is Q.
    """

    def __init__(self, obs_space: gym.Space, n_actions: int, n_objectives: int,
                 hidden: Sequence[int] = (256, 256, 256), obs_encoding: str = "scale", n_components: int = 12,
                 n_critics: int = 1, layer_norm: bool = False) -> None:
        super().__init__()
        self.encoder = ObsEncoder(obs_space, obs_encoding)
        self.n_actions = n_actions
        self.n_objectives = n_objectives
        self.n_components = n_components
        self.n_critics = n_critics
        self.net = mlp(self.encoder.out_dim, hidden, n_critics * n_actions * n_components * n_objectives, layer_norm)

    def components(self, obs: torch.Tensor, feats: torch.Tensor | None = None) -> torch.Tensor:
        """``(B, H, |A|, C, m)`` the return vectors of every head for raw observations ``(B, ...)``; ``feats``, if
        given, is their encoding (``self.encoder(obs)``, which has no parameters: an update encodes a batch once for
        every network)."""
        x = self.encoder(obs) if feats is None else feats
        return self.net(x).view(-1, self.n_critics, self.n_actions, self.n_components, self.n_objectives)

    @staticmethod
    def select(v: torch.Tensor, prefs: torch.Tensor) -> torch.Tensor:
        """The preferred component of each head and action: ``v (B, H, A, C, m)``, ``prefs (B, K, m)`` ->
        ``(B, H, K, A, m)``."""
        b, h, a, c, m = v.shape
        k = prefs.shape[1]
        # max(...).indices, not argmax: the same first maximum, several times faster on CPU for a short last dim
        best = torch.einsum("bkm,bhacm->bhkac", prefs, v).max(dim=4).indices  # (B, H, K, A)
        return v.unsqueeze(2).expand(b, h, k, a, c, m).gather(
            4, best[..., None, None].expand(b, h, k, a, 1, m)).squeeze(4)

    @staticmethod
    def select_one(v: torch.Tensor, prefs: torch.Tensor) -> torch.Tensor:
        """The preferred component of one action per row: ``v (X, C, m)``, ``prefs (X, K, m)`` -> ``(X, K, m)``.

        What the loss needs (the taken action only): :meth:`select` over every action and then the taken one give
        the same values at ``|A|`` times the cost, and a backward pass through an expanded ``(X, K, A, C, m)``
        gather.
        """
        x, c, m = v.shape
        best = torch.bmm(prefs, v.transpose(1, 2)).max(dim=2).indices  # (X, K): w^T v_c, best c
        return v.gather(1, best[..., None].expand(x, prefs.shape[1], m))

    @staticmethod
    def pessimistic(q: torch.Tensor, prefs: torch.Tensor) -> torch.Tensor:
        """Maxmin over heads: ``q (B, H, K, A, m)``, ``prefs (B, K, m)`` -> ``(B, K, A, m)``, per (row, preference,
        action) the head with the lowest scalarised value."""
        if q.shape[1] == 1:
            return q[:, 0]
        b, h, k, a, m = q.shape
        worst = torch.einsum("bkm,bhkam->bhka", prefs, q).argmin(dim=1, keepdim=True)  # (B, 1, K, A)
        return q.gather(1, worst[..., None].expand(b, 1, k, a, m)).squeeze(1)

    @staticmethod
    def double_q_values(v_online: torch.Tensor, v_target: torch.Tensor, prefs: torch.Tensor
                        ) -> tuple[torch.Tensor, torch.Tensor]:
        """Greedy actions and double-Q values at each row's own preference, from one head's components.

        ``v_online``, ``v_target`` ``(X, A, C, m)``, ``prefs`` ``(X, N, m)``. The online network picks the action
        (its best component over all actions, ``argmax_{a, c} w^T v_online``); the target network's value of that
        action is its own component that ``w`` prefers. The same numbers as :meth:`forward_prefs` of both
        networks followed by :func:`mope.agent.losses.envelope_target` with ``envelope=False``, at a fraction of the
        cost.

        Returns:
            ``(values (X, N, m), greedy (X, N))``.
        """
        x, a, c, m = v_online.shape
        n = prefs.shape[1]
        p_t = prefs.transpose(1, 2)  # (X, m, N)
        # Scores (X, A, C, N): the reductions below then run over outer axes, several times faster on the CPU than
        # max(...).indices over a short innermost one; amax over C first, then the first best action: the same
        # action as the first maximum over the flattened (a, c).
        s_on = torch.bmm(v_online.reshape(x, a * c, m), p_t).view(x, a, c, n)
        greedy = s_on.amax(dim=2).max(dim=1).indices  # (X, N)
        s_tg = torch.bmm(v_target.reshape(x, a * c, m), p_t).view(x, a, c, n)
        s_act = s_tg.gather(1, greedy.view(x, 1, 1, n).expand(x, 1, c, n)).squeeze(1)  # (X, C, N): action greedy
        best = greedy * c + s_act.max(dim=1).indices  # (X, N): the flat (a, c) of the target's value
        return v_target.reshape(x, a * c, m).gather(1, best.unsqueeze(-1).expand(x, n, m)), greedy

    def forward(self, obs: torch.Tensor, pref: torch.Tensor) -> torch.Tensor:
        """``(R, |A|, m)`` Q-vectors of ``R`` observations, each under its own preference ``(R, m)``."""
        return self.forward_prefs(obs, pref.unsqueeze(1)).squeeze(1)

    def forward_prefs(self, obs: torch.Tensor, prefs: torch.Tensor) -> torch.Tensor:
        """``(B, K, |A|, m)`` Q-vectors of each observation under K preferences; one network pass of ``B`` rows."""
        return self.pessimistic(self.select(self.components(obs), prefs), prefs)

    def greedy(self, obs: torch.Tensor, pref: torch.Tensor) -> torch.Tensor:
        """``(R,)`` greedy actions ``argmax_a w^T Q(s, a, w)`` of ``R`` observations, each under its own ``(R, m)``.

        With one head, ``w^T Q(s, a, w) = max_c w^T v_c(s, a)``, so the scores of all (a, c) at once are enough
        (the first best action on ties); with several heads, the maxmin of :meth:`forward`.
        """
        if self.n_critics > 1:
            return torch.einsum("bm,bam->ba", pref, self(obs, pref)).argmax(dim=1)
        v = self.components(obs)[:, 0]  # (R, A, C, m)
        r, a, c, m = v.shape
        scores = torch.bmm(v.reshape(r, a * c, m), pref.unsqueeze(2)).view(r, a, c)
        return scores.amax(dim=2).max(dim=1).indices


Q_HEADS = ("conditioned", "convex")


def make_q_network(obs_space: gym.Space, n_actions: int, n_objectives: int, hidden: Sequence[int],
                   obs_encoding: str, head: str = "conditioned", n_components: int = 12,
                   n_critics: int = 1, layer_norm: bool = False) -> nn.Module:
    """The Q-network of a config: :class:`QNetwork` (``conditioned``, the paper's) or :class:`ConvexQNetwork`."""
    if head == "convex":
        return ConvexQNetwork(obs_space, n_actions, n_objectives, hidden, obs_encoding, n_components, n_critics,
                              layer_norm)
    return QNetwork(obs_space, n_actions, n_objectives, hidden, obs_encoding, layer_norm)


class Discriminator(nn.Module):
    """q_phi(omega | s): logits of a categorical distribution over the N_I preference cells (eq. 6).

    Three fully connected layers: ``obs -> hidden[0] -> hidden[1] -> N_I``.
    """

    def __init__(self, obs_space: gym.Space, n_cells: int, hidden: Sequence[int] = (64, 64),
                 obs_encoding: str = "scale") -> None:
        super().__init__()
        self.encoder = ObsEncoder(obs_space, obs_encoding)
        self.n_cells = n_cells
        self.net = mlp(self.encoder.out_dim, hidden, n_cells)

    def forward(self, obs: torch.Tensor) -> torch.Tensor:
        """``(B, N_I)`` logits for raw observations ``(B, ...)``."""
        return self.net(self.encoder(obs))

    def log_prob(self, obs: torch.Tensor, cells: torch.Tensor, feats: torch.Tensor | None = None) -> torch.Tensor:
        """``log q_phi(cell | s)`` for each row; ``feats``, if given, is ``self.encoder(obs)``."""
        logits = self.net(self.encoder(obs) if feats is None else feats)
        return torch.log_softmax(logits, dim=1).gather(1, cells.long().view(-1, 1)).squeeze(1)
