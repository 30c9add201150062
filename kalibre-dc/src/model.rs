//! The built-in simulator as a kalibre [`kalibre_core::Model`].
