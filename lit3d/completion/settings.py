"""The completion task's settings as frozen dataclasses, one per config node of ``task``
(:class:`~lit3d.completion.module.CompletionTask`):

    task.optimizer    the two Adams and the generator's loss scale (:class:`OptimizerSettings`)
    task.loss         the weights of the generator's objective (:class:`LossWeights`)
    task.adversarial  the critic, its updates and its gradient penalty (:class:`AdversarialSettings`)
    task.panels       validation panels and meshes (:class:`PanelSettings`)

:func:`parse` turns a node (a mapping, None for the defaults, or the dataclass itself) into its dataclass;
an unknown key is a ValueError naming ``task.<node>.<key>``. Sequences become tuples. Checkpoints written
before these nodes hold the keys flat: :mod:`lit3d.completion.checkpoint_upgrade` moves them.
"""
from __future__ import annotations

from dataclasses import dataclass

from lit3d.completion.losses import PENALTY_PRECISIONS
from lit3d.utils.settings_nodes import parse_node


@dataclass(frozen=True)
class OptimizerSettings:
    """Adam for the generator (and classifier) at ``lr_g``, for the critic at ``lr_d``, both with ``betas`` and
    ``eps``; ``loss_scale``: a factor of the generator objective for the optimiser only, a number or
    ``voxels`` (= R^3; :func:`lit3d.completion.losses.resolve_loss_scale`), applied as its eps / scale."""

    lr_g: float = 1e-4
    lr_d: float = 1e-4
    betas: tuple[float, float] = (0.9, 0.999)
    eps: float = 1e-8
    loss_scale: float | str = 1.0

    def __post_init__(self):
        object.__setattr__(self, "betas", tuple(self.betas))


@dataclass(frozen=True)
class LossWeights:
    """The generator's objective ``gamma * BCE + stage_weight * stage BCE + (1 - gamma) * adversarial + zeta *
    classifier CE``; ``alpha``: the weight of empty voxels in the BCE."""

    alpha: float = 0.35
    gamma: float = 0.8
    zeta: float = 0.01
    stage_weight: float = 0.0


@dataclass(frozen=True)
class AdversarialSettings:
    """``use``: a critic (WGAN-GP) joins after ``start_epoch`` epochs of reconstruction only (false: BCE and
    classifier only); ``critic_steps`` critic updates per generator update, the penalty x ``gp_lambda`` on every
    ``gp_every``-th of them (weighted ``gp_every`` times), its critic pass in ``gp_precision`` (fp32 | bf16);
    ``critic_concat``: real and fake shapes scored in one critic pass."""

    use: bool = True
    start_epoch: int = 0
    critic_steps: int = 1
    gp_lambda: float = 10.0
    gp_every: int = 1
    critic_concat: bool = False
    gp_precision: str = "fp32"

    def __post_init__(self):
        if int(self.gp_every) < 1:
            raise ValueError(f"task.adversarial.gp_every={self.gp_every}: the gradient penalty runs every N >= 1 "
                             "critic updates")
        if self.gp_precision not in PENALTY_PRECISIONS:
            raise ValueError(f"task.adversarial.gp_precision={self.gp_precision!r}: one of {', '.join(PENALTY_PRECISIONS)}")


@dataclass(frozen=True)
class PanelSettings:
    """``val/panels`` (a rendered figure) every ``image_every_n_epochs`` epochs; ``val/mesh/{prediction,target}``
    (marching cubes) every ``mesh_every_n_epochs`` (0: never)."""

    image_every_n_epochs: int = 1
    mesh_every_n_epochs: int = 0


def parse(cls, node, name: str):
    """``node`` (a mapping, None for the defaults, or already a ``cls``) as a ``cls``; ValueError naming
    ``task.<name>.<key>`` for a key ``cls`` does not have (:func:`lit3d.utils.settings_nodes.parse_node`)."""
    return parse_node(cls, node, f"task.{name}")
