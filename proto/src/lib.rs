//! Wire messages between master, workers and submitters (the farm issue fills this crate).
