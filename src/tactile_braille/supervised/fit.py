"""The supervised fit loop shared by the key classifier and the touch encoder.

Epochs of shuffled mini-batches (one permutation per epoch from the caller's
``torch.Generator``), a loss per batch from a callback, an optimiser step and
an optional scheduler step after each; then a per-epoch callback, which may
stop the fit early. What differs between the models stays with them: the
classifier's augmentation is in its loss callback, its validation, early
stopping and per-epoch learning-rate decay in its epoch callback; the touch
encoder's one-cycle schedule is the per-step scheduler.
"""

from __future__ import annotations

from collections.abc import Callable

import torch
from torch import nn


def fit_minibatches(
    model: nn.Module,
    size: int,
    loss: Callable[[torch.Tensor], torch.Tensor],
    optimiser: torch.optim.Optimizer,
    epochs: int,
    batch_size: int,
    generator: torch.Generator,
    schedule: torch.optim.lr_scheduler.LRScheduler | None = None,
    end_epoch: Callable[[int, float], bool] | None = None,
) -> int:
    """Fit ``model`` for at most ``epochs`` passes over ``size`` samples; returns the epochs run.

    Args:
        model: put in train mode at the start of every epoch (an epoch callback may evaluate it).
        size: number of training samples; batches are CPU index tensors into ``range(size)``.
        loss: the scalar loss of a batch of indices (the model's forward pass happens here).
        optimiser: stepped after every batch (gradients set to None before the backward pass).
        epochs: passes at most.
        batch_size: indices per batch (the last batch of an epoch may be smaller).
        generator: draws each epoch's permutation (``torch.randperm(size, generator=...)``).
        schedule: a learning-rate scheduler stepped after every optimiser step, or None.
        end_epoch: called after every epoch with its index and its mean training loss (the batches'
            losses weighted by their sizes); returns True to stop. Without it the losses are not read
            (no device synchronisation).
    """
    for epoch in range(epochs):
        model.train()
        losses: list[tuple[torch.Tensor, int]] = []
        for batch in torch.randperm(size, generator=generator).split(batch_size):
            value = loss(batch)
            optimiser.zero_grad(set_to_none=True)
            value.backward()
            optimiser.step()
            if schedule is not None:
                schedule.step()
            if end_epoch is not None:
                losses.append((value.detach(), len(batch)))
        if end_epoch is not None:
            total = 0.0
            for value, count in losses:
                total += value.item() * count
            if end_epoch(epoch, total / size):
                return epoch + 1
    return epochs


def adam(parameters, learning_rate: float, eps: float = 1e-8) -> torch.optim.Adam:
    """Adam, fused when the parameters' device supports it (CPU and CUDA do in PyTorch >= 2.4)."""
    parameters = list(parameters)
    try:
        return torch.optim.Adam(parameters, lr=learning_rate, eps=eps, fused=True)
    except (RuntimeError, ValueError):  # device without a fused kernel
        return torch.optim.Adam(parameters, lr=learning_rate, eps=eps)
