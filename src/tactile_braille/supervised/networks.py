"""The paper's convolutions, written once for every network that looks at a tactile image.

The paper's networks all start with the Atari CNN: conv 32/64/64 filters,
kernels 8/4/3, strides 4/2/1, each followed by a ReLU, no pooling, then the
feature maps flattened (64 * 9 * 9 = 5,184 features of a 100x100 image).
:func:`conv_stack` builds it, with a BatchNorm after each ReLU for the key
classifier (:class:`~tactile_braille.supervised.classifier.KeyClassifier`);
:class:`Encoder` is the plain stack over uint8 or float images, used by the
touch encoder (:mod:`~tactile_braille.supervised.touch`) and by the agents'
networks (:mod:`~tactile_braille.agents.networks`). :func:`he_init` is their
variance-scaling (He) initialisation.

It lives with the supervised models, the lowest layer that uses it, so that
the agents (a layer above) build on it too.

>>> conv_output_size()
5184
>>> conv_output_size(84)
3136
"""

from __future__ import annotations

import torch
from torch import nn

IMAGE_SIZE_PX = 100  # the processed tactile image's side (SensorConfig.size_px's default)
CHANNELS = (32, 64, 64)
KERNELS = (8, 4, 3)
STRIDES = (4, 2, 1)


def conv_output_size(image_size_px: int = IMAGE_SIZE_PX) -> int:
    """Length of :func:`conv_stack`'s flattened features of a square image of this side."""
    side = image_size_px
    for kernel, stride in zip(KERNELS, STRIDES, strict=True):
        side = (side - kernel) // stride + 1
        if side < 1:
            raise ValueError(f"an image of {image_size_px} px is too small for the paper's convolutions")
    return CHANNELS[-1] * side * side


def conv_stack(batch_norm: bool = False, channels: int = 1) -> nn.Sequential:
    """The paper's convolutions on images of ``channels`` channels (one: the paper's), then a Flatten.

    Conv, ReLU (and, with ``batch_norm``, a BatchNorm) for each of the three
    layers, in that order: a ``Sequential`` whose indices (``0``, ``2``, ...)
    name the layers in state dicts. Its weights are PyTorch's default
    initialisation (drawn from the global RNG as the layers are made): apply
    :func:`he_init` for the paper's.
    """
    layers: list[nn.Module] = []
    inputs = channels
    for outputs, kernel, stride in zip(CHANNELS, KERNELS, STRIDES, strict=True):
        layers += [nn.Conv2d(inputs, outputs, kernel, stride=stride), nn.ReLU()]
        if batch_norm:
            layers.append(nn.BatchNorm2d(outputs))
        inputs = outputs
    layers.append(nn.Flatten())
    return nn.Sequential(*layers)


def he_init(module: nn.Module) -> None:
    """Variance-scaling (He) weights and zero biases for a convolution or dense layer, else nothing.

    For ``module.apply(he_init)``: it draws from the global RNG, layer after layer in module order.
    """
    if isinstance(module, nn.Conv2d | nn.Linear):
        nn.init.kaiming_normal_(module.weight, nonlinearity="relu")
        nn.init.zeros_(module.bias)


class Encoder(nn.Module):
    """The paper's convolutions (:func:`conv_stack`, He-initialised) over a (B, 1, 100, 100) uint8 or
    float image; uint8 images are scaled to [0, 1]."""

    output_size = conv_output_size()

    def __init__(self, channels: int = 1) -> None:
        super().__init__()
        self.layers = conv_stack(channels=channels)
        self.apply(he_init)

    def forward(self, images: torch.Tensor) -> torch.Tensor:
        if images.dtype == torch.uint8:
            images = images.float().div_(255.0)
        return self.layers(images)
