//! The thermal graph surrogate of the Kalibre paper, and its search regulariser.
