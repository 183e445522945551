"""Reports of a fused track: the interactive HTML map (:mod:`.html`), and the atomic
file writing they share (:mod:`.atomic`)."""

from __future__ import annotations
