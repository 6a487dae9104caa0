//! The levelmap service runtime (ARCHITECTURE.md): what the services share around the wire
//! contract ([`wire`]) to run. [`session`]: the Zenoh session of a service (mode, endpoints,
//! TLS), the config loader ([`session::load_toml`], with [`session::env`] overrides), the
//! clock ([`session::now_ns`]) and the stop signals ([`session::shutdown_signal`]). [`ros2`]:
//! ROS 2 topics on Zenoh keys, publishers and liveliness tokens as rmw_zenoh makes them.
//! [`priority`]: background threads that yield to the service's own.
//! `recording` (feature `recording`): MCAP recordings of the bus's traffic.

pub mod priority;
#[cfg(feature = "recording")]
pub mod recording;
pub mod ros2;
pub mod session;
