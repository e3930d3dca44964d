"""The workbook's networks: shared blocks and one file per model (WholeGrasp-VAE, MotionFill-VAE, GNet, MNet, WANDR)."""
from graspkit.models.blocks import GaussianHead, ResBlock, kl_standard_normal, mlp, reparameterize, robust_kl

__all__ = ["ResBlock", "mlp", "GaussianHead", "reparameterize", "kl_standard_normal", "robust_kl"]
