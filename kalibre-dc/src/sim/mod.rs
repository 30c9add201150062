//! The built-in thermal simulator (reduced-order 3-D flow and heat on a structured grid).
