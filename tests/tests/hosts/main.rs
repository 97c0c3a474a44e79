//! One team over several hosts: network namespaces, mutual TLS, the keys.
//!
//! One test binary (each file a module): the files share one link of the harness.

mod hosts;
mod hosts_steer_realtime;
mod key_permissions;
mod secure_link;
