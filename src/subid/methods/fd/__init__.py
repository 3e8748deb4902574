"""Identification from frequency-response data (:class:`subid.FRData`): subspace and refinement."""
