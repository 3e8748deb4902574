"""Identification methods: discrete-time batch (``dt``), continuous-time batch (``ct``) and online (``online``)."""
