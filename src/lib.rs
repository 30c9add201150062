//! kalibre facade
