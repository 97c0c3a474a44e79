//! The viewer's HTTP server (tiny_http on its own threads): `/` is the page, `/scene.json` the
//! live scene, `/events` a Server-Sent Events stream of frames. The team's loop only hands
//! frames to a [`Hub`], which never blocks: a client that cannot keep up loses frames, never
//! the team its speed.

use std::io::Write;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::mpsc::{sync_channel, Receiver, SyncSender, TrySendError};
use std::sync::{Arc, Mutex, MutexGuard};
use std::thread::JoinHandle;
use std::time::Duration;

/// Frames a slow client may have queued before it loses the newest ones.
const CLIENT_QUEUE: usize = 64;

/// Requests answered at once, each on its own thread: a client that asks for the page (MBs for
/// a long replay) and never reads blocks only its own thread's write, never another client's.
/// Past this many, a request is answered 503 at once (a reply small enough for the socket's
/// buffer, so even that never blocks the accepting thread).
const MAX_RESPONDERS: usize = 64;

/// Counts a responder thread while it lives (also when its handler panics).
struct Responding(Arc<AtomicUsize>);

impl Drop for Responding {
    fn drop(&mut self) {
        self.0.fetch_sub(1, Ordering::SeqCst);
    }
}

/// The server could not start.
#[derive(Debug, thiserror::Error)]
pub enum ServeError {
    #[error("--serve {addr}: cannot listen: {detail}")]
    Bind { addr: String, detail: String },
}

/// What live clients are sent: the scene, the frames so far (without positions: the curves)
/// and the newest full frame. Cloned `Arc<str>` events go to every client's bounded queue.
#[derive(Default)]
pub struct Hub {
    state: Mutex<HubState>,
}

#[derive(Default)]
struct HubState {
    scene_json: String,
    history: Vec<Arc<str>>,
    newest: Option<Arc<str>>,
    ended: Option<Arc<str>>,
    clients: Vec<SyncSender<Arc<str>>>,
}

impl Hub {
    fn lock(&self) -> MutexGuard<'_, HubState> {
        // A client thread that panicked cannot leave the plain data inconsistent.
        self.state.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// Sets the scene clients fetch first.
    pub fn set_scene(&self, json: String) {
        self.lock().scene_json = json;
    }

    /// Sends a frame event (`full`) to every client and keeps its curve-only form (`light`) for
    /// clients that join later.
    pub fn frame(&self, full: String, light: String) {
        let event: Arc<str> = format!("event: frame\ndata: {full}\n\n").into();
        let mut st = self.lock();
        st.history
            .push(format!("event: frame\ndata: {light}\n\n").into());
        st.newest = Some(event.clone());
        broadcast(&mut st.clients, &event);
    }

    /// Sends the end of the run (the final verdict); the page then closes its stream.
    pub fn end(&self, json: String) {
        let event: Arc<str> = format!("event: end\ndata: {json}\n\n").into();
        let mut st = self.lock();
        st.ended = Some(event.clone());
        broadcast(&mut st.clients, &event);
    }

    fn subscribe(&self) -> (Vec<Arc<str>>, Receiver<Arc<str>>) {
        let (tx, rx) = sync_channel(CLIENT_QUEUE);
        let mut st = self.lock();
        let mut backlog = st.history.clone();
        backlog.extend(st.newest.clone());
        backlog.extend(st.ended.clone());
        st.clients.push(tx);
        (backlog, rx)
    }
}

/// Queue an event for every client; forget clients that went away.
fn broadcast(clients: &mut Vec<SyncSender<Arc<str>>>, event: &Arc<str>) {
    clients.retain(|c| match c.try_send(event.clone()) {
        Ok(()) | Err(TrySendError::Full(_)) => true,
        Err(TrySendError::Disconnected(_)) => false,
    });
}

/// A running server; dropping it stops accepting requests.
pub struct Server {
    server: Arc<tiny_http::Server>,
    accept: Option<JoinHandle<()>>,
    /// The address it listens on (the port resolved when 0 was asked).
    pub addr: String,
}

impl Drop for Server {
    fn drop(&mut self) {
        self.server.unblock();
        if let Some(h) = self.accept.take() {
            let _ = h.join();
        }
    }
}

/// Serves `page` at `/`; with a hub, also `/scene.json` and `/events`.
pub fn serve_page(addr: &str, page: String, hub: Option<Arc<Hub>>) -> Result<Server, ServeError> {
    let server = tiny_http::Server::http(addr).map_err(|e| ServeError::Bind {
        addr: addr.to_owned(),
        detail: e.to_string(),
    })?;
    let bound = server
        .server_addr()
        .to_ip()
        .map_or_else(|| addr.to_owned(), |a| a.to_string());
    let server = Arc::new(server);
    let accepting = server.clone();
    let page: Arc<str> = page.into();
    let accept = std::thread::Builder::new()
        .name("viewer-http".into())
        .spawn(move || {
            // `incoming_requests` ends when the server is unblocked (on drop).
            let busy = Arc::new(AtomicUsize::new(0));
            for request in accepting.incoming_requests() {
                if busy.fetch_add(1, Ordering::SeqCst) >= MAX_RESPONDERS {
                    drop(Responding(busy.clone()));
                    let _ = request.respond(tiny_http::Response::empty(503));
                    continue;
                }
                let guard = Responding(busy.clone());
                let (page, hub) = (page.clone(), hub.clone());
                // A thread that cannot start drops the request (its connection closes).
                let _ = std::thread::Builder::new()
                    .name("viewer-respond".into())
                    .spawn(move || {
                        let _guard = guard;
                        handle(request, &page, hub.as_ref());
                    });
            }
        })
        .map_err(|e| ServeError::Bind {
            addr: addr.to_owned(),
            detail: e.to_string(),
        })?;
    Ok(Server {
        server,
        accept: Some(accept),
        addr: bound,
    })
}

fn handle(request: tiny_http::Request, page: &Arc<str>, hub: Option<&Arc<Hub>>) {
    let path = request.url().split('?').next().unwrap_or("/").to_owned();
    let respond = |request: tiny_http::Request, body: String, kind: &str| {
        let mut response = tiny_http::Response::from_string(body);
        for (name, value) in [("Content-Type", kind), ("Cache-Control", "no-store")] {
            if let Ok(h) = tiny_http::Header::from_bytes(name, value) {
                response.add_header(h);
            }
        }
        let _ = request.respond(response);
    };
    match (path.as_str(), hub) {
        ("/" | "/index.html", _) => respond(request, page.to_string(), "text/html; charset=utf-8"),
        ("/scene.json", Some(hub)) => {
            let json = hub.lock().scene_json.clone();
            respond(request, json, "application/json")
        }
        // On this request's own thread: a slow browser only slows its own writes.
        ("/events", Some(hub)) => stream_events(request, hub),
        _ => {
            let _ = request.respond(tiny_http::Response::empty(404));
        }
    }
}

fn stream_events(request: tiny_http::Request, hub: &Hub) {
    let (backlog, rx) = hub.subscribe();
    let mut out = request.into_writer();
    let head = "HTTP/1.1 200 OK\r\nContent-Type: text/event-stream\r\nCache-Control: no-store\r\n\
                Connection: close\r\n\r\n";
    if out.write_all(head.as_bytes()).is_err() {
        return;
    }
    for event in backlog {
        if out.write_all(event.as_bytes()).is_err() {
            return;
        }
    }
    let _ = out.flush();
    // Ends when the hub is dropped (the run is over) or the browser goes away.
    loop {
        match rx.recv_timeout(Duration::from_secs(15)) {
            Ok(event) => {
                if out
                    .write_all(event.as_bytes())
                    .and_then(|()| out.flush())
                    .is_err()
                {
                    return;
                }
            }
            // An SSE comment keeps idle connections (and proxies) open.
            Err(std::sync::mpsc::RecvTimeoutError::Timeout) => {
                if out
                    .write_all(b": idle\n\n")
                    .and_then(|()| out.flush())
                    .is_err()
                {
                    return;
                }
            }
            Err(std::sync::mpsc::RecvTimeoutError::Disconnected) => return,
        }
    }
}
