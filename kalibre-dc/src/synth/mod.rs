//! Synthetic halls with a hidden truth: presets `demo`, `hall-a`, `hall-b`.
