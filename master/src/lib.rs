//! The farm master: scheduling, load balancing and compositing (the farm issue fills this crate).
