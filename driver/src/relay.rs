//! The relay's TCP side: accept clients, shuttle bytes between each socket and its
//! [`comms::relay::Session`], which lives inside the driver next to the replica.

use std::future::Future;
use std::io;

use tokio::net::{TcpListener, TcpStream};

use comms::relay::{CloseReason, ErrCode, SessionState};

use crate::handle::Handle;

/// Accepts relay clients on `listener` until `shutdown` completes. Each client runs as a
/// local task on this thread (call this inside a [`tokio::task::LocalSet`] on the
/// driver's thread); a failing or cut-off client never affects the others. Beyond
/// [`crate::DriverConfig::max_relay_clients`] connected clients, a new connection gets
/// one line `ERR 503 ...` and is closed (counted in
/// [`crate::IoStats::relay_clients_refused`]).
pub async fn serve(listener: TcpListener, handle: Handle, shutdown: impl Future<Output = ()>) {
    tokio::pin!(shutdown);
    loop {
        tokio::select! {
            () = &mut shutdown => return,
            accepted = listener.accept() => match accepted {
                Ok((stream, peer)) => {
                    let _ = stream.set_nodelay(true);
                    // Opened here, not in the task: a burst of connections is counted
                    // against the cap as it is accepted.
                    let opened = handle.inner().borrow_mut().open_session();
                    match opened {
                        Some(session) => {
                            tracing::debug!(%peer, "relay client connected");
                            tokio::task::spawn_local(connection(stream, handle.clone(), peer, session));
                        }
                        None => refuse(stream, handle.inner().borrow().max_relay_clients),
                    }
                }
                // Out of file descriptors and the like: keep serving the others.
                Err(e) => {
                    tracing::warn!(error = %e, "relay accept failed");
                    tokio::time::sleep(std::time::Duration::from_millis(50)).await;
                }
            }
        }
    }
}

/// Answers a connection over the cap with one line and closes it. The socket is fresh,
/// so the line fits its send buffer at once; a client that cannot take even that gets
/// nothing (no task waits for it).
fn refuse(stream: TcpStream, max: usize) {
    let line = format!(
        "ERR {} too many relay clients ({max} connected, --max-clients); try again later\n",
        ErrCode::Unavailable
    );
    let _ = stream.try_write(line.as_bytes());
    drop(stream);
}

async fn connection(
    stream: TcpStream,
    handle: Handle,
    peer: std::net::SocketAddr,
    (id, notify): (u64, std::rc::Rc<tokio::sync::Notify>),
) {
    let mut buf = vec![0u8; 16 * 1024];
    let outcome: io::Result<()> = async {
        loop {
            let (finished, has_output) = {
                let inner = handle.inner().borrow();
                match inner.sessions.get(&id) {
                    Some(slot) => (
                        slot.session.is_finished(),
                        !slot.session.pending_output().is_empty(),
                    ),
                    None => (true, false),
                }
            };
            if finished {
                return Ok(());
            }
            tokio::select! {
                biased;
                ready = stream.writable(), if has_output => {
                    ready?;
                    let mut inner = handle.inner().borrow_mut();
                    if let Some(slot) = inner.sessions.get_mut(&id) {
                        match stream.try_write(slot.session.pending_output()) {
                            Ok(n) => slot.session.consume_output(n),
                            Err(e) if e.kind() == io::ErrorKind::WouldBlock => {}
                            Err(e) => return Err(e),
                        }
                    }
                }
                ready = stream.readable() => {
                    ready?;
                    match stream.try_read(&mut buf) {
                        Ok(0) => return Ok(()),
                        Ok(n) => handle.inner().borrow_mut().session_input(id, &buf[..n]),
                        Err(e) if e.kind() == io::ErrorKind::WouldBlock => {}
                        Err(e) => return Err(e),
                    }
                }
                () = notify.notified() => {}
            }
        }
    }
    .await;
    let state = {
        let mut inner = handle.inner().borrow_mut();
        let state = inner.sessions.remove(&id).map(|s| s.session.state());
        if state == Some(SessionState::Closed(CloseReason::OutputOverflow)) {
            inner.io.relay_cutoffs += 1;
        }
        state
    };
    match (state, outcome) {
        (Some(SessionState::Closed(CloseReason::OutputOverflow)), _) => {
            tracing::warn!(%peer, "relay client cut off: it does not read its output")
        }
        (_, Err(e)) => tracing::debug!(%peer, error = %e, "relay client connection failed"),
        _ => tracing::debug!(%peer, "relay client disconnected"),
    }
}
