"""Fitting effect models to real scans."""
