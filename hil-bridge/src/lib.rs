//! # hil-bridge
#![no_std]
