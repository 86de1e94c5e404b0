//! The sensor controller's logic.
#![no_std]
