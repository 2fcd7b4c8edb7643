//! The farm scheduler (in progress).
