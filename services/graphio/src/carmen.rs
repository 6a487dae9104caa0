//! CARMEN logs.
