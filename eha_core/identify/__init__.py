"""Identification: least squares (time domain) and transfer-function estimation."""
