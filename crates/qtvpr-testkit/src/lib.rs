//! What the tests of every crate of the workspace share, so that none includes another
//! crate's file by path: the real data of `../shared/data` ([`data`]) and the zip
//! archives, hostile ones among them, that every reader of an `.npz` is tested on
//! ([`zip`]). A dev-dependency only: nothing the library or a front end ships.

pub mod data;
pub mod zip;
