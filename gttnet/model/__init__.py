"""GTT-Net: continuous-convolution U-Net, affinity head, PointNet stream and the network that composes them."""

from __future__ import annotations

from gttnet.model.network import GTTNet, GTTNetConfig, build_model, gttnet_base, gttnet_pointnet, gttnet_tiny

__all__ = ["GTTNet", "GTTNetConfig", "build_model", "gttnet_tiny", "gttnet_base", "gttnet_pointnet"]
