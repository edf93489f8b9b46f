"""Estimators: initiation, EKF, iSAM2, fixed-lag and offline smoothers."""
