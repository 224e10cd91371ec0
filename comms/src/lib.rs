//! comms: huddle's blackboard, its wire format and the sans-IO replication core, talk
//! queues, arbitration, the relay line protocol and the tokio/socket2 driver.
//! (Being built: see issue "The blackboard and its replication core".)
pub mod arbitration;
