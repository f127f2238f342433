//! The smallest HTTP/1.1 server `fogray view` needs, around the `httparse` parser: GET (and
//! HEAD) requests without a body, one request a connection, answered whole.
//!
//! Every resource a client can make it use is bounded, which a general-purpose server would
//! leave to configuration: a request's head is at most [`MAX_HEAD`] bytes (431 above), at most
//! [`MAX_CONNECTIONS`] connections are served at once (503 beyond), and a client that sends
//! nothing for [`READ_TIMEOUT`] is dropped. It listens on 127.0.0.1 only, and answers only
//! requests whose `Host` is that address or `localhost`, so that a web page elsewhere cannot
//! reach it by rebinding its own name to 127.0.0.1.

use std::io::{self, Read, Write};
use std::net::{Ipv4Addr, SocketAddr, TcpListener, TcpStream};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::Duration;

use fogray_fit::interrupt::StopFlag;

/// The most bytes a request's line and headers may take.
pub const MAX_HEAD: usize = 8 * 1024;

/// The most headers a request may have.
const MAX_HEADERS: usize = 32;

/// The most connections served at once (each holds a thread and a head buffer).
pub const MAX_CONNECTIONS: usize = 8;

/// How long a connection may send nothing before it is dropped.
pub const READ_TIMEOUT: Duration = Duration::from_secs(5);

/// How long a slow reader may take to accept a response's bytes.
const WRITE_TIMEOUT: Duration = Duration::from_secs(30);

/// How often the accept loop looks at the stop flag when no one connects.
const POLL: Duration = Duration::from_millis(20);

/// A request, as the handler sees it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Request {
    /// The path, still percent-encoded (routes compare it whole, so no decoding can turn it
    /// into another route).
    pub path: String,
    /// The query string after `?`, still percent-encoded (empty when none).
    pub query: String,
}

/// A response, sent whole with its length.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Response {
    /// The status code.
    pub status: u16,
    /// The `Content-Type`.
    pub content_type: &'static str,
    /// The body.
    pub body: Vec<u8>,
}

impl Response {
    /// A 200 response.
    pub fn ok(content_type: &'static str, body: Vec<u8>) -> Response {
        Response {
            status: 200,
            content_type,
            body,
        }
    }

    /// A refusal: `status` and one line of text saying why.
    pub fn refuse(status: u16, message: &str) -> Response {
        let line = message.replace(['\n', '\r'], " ");
        Response {
            status,
            content_type: "text/plain; charset=utf-8",
            body: format!("{line}\n").into_bytes(),
        }
    }
}

/// What answers the requests.
pub trait Handler: Sync {
    /// The response to `request` (a GET; HEAD gets the same without its body).
    fn handle(&self, request: &Request) -> Response;
}

/// A listener on 127.0.0.1 at `port` (0: one the system chooses).
///
/// Errors: the port is taken or not ours to bind.
pub fn bind(port: u16) -> io::Result<TcpListener> {
    TcpListener::bind(SocketAddr::from((Ipv4Addr::LOCALHOST, port)))
}

/// Serves `listener` with `handler` until `stop` is raised; connections under way then finish
/// (each bounded by the timeouts) before it returns.
///
/// Errors: the listener cannot be made non-blocking.
pub fn serve(listener: &TcpListener, handler: &dyn Handler, stop: &StopFlag) -> io::Result<()> {
    // Non-blocking, so that the loop sees the stop flag without a connection to wake it.
    listener.set_nonblocking(true)?;
    let port = listener.local_addr()?.port();
    let active = AtomicUsize::new(0);
    std::thread::scope(|scope| {
        while !stop.is_raised() {
            let stream = match listener.accept() {
                Ok((stream, _)) => stream,
                Err(e) if e.kind() == io::ErrorKind::WouldBlock => {
                    std::thread::sleep(POLL);
                    continue;
                }
                // A connection reset before it was accepted, or no descriptor left for the
                // moment: the next one may do better; the server goes on.
                Err(_) => {
                    std::thread::sleep(POLL);
                    continue;
                }
            };
            if active.load(Ordering::Acquire) >= MAX_CONNECTIONS {
                let _ = prepare(&stream).and_then(|()| {
                    send(
                        &stream,
                        false,
                        &Response::refuse(503, "busy: too many connections at once"),
                    )
                });
                continue;
            }
            active.fetch_add(1, Ordering::AcqRel);
            let active = &active;
            let spawned = std::thread::Builder::new().spawn_scoped(scope, move || {
                // A client that goes away mid-request is no error of the server's.
                let _ = connection(&stream, handler, port);
                active.fetch_sub(1, Ordering::AcqRel);
            });
            // No thread to be had: this connection is dropped unanswered, the server goes on.
            if spawned.is_err() {
                active.fetch_sub(1, Ordering::AcqRel);
            }
        }
    });
    Ok(())
}

/// Blocking reads and writes with timeouts (an accepted stream may inherit non-blocking).
fn prepare(stream: &TcpStream) -> io::Result<()> {
    stream.set_nonblocking(false)?;
    stream.set_read_timeout(Some(READ_TIMEOUT))?;
    stream.set_write_timeout(Some(WRITE_TIMEOUT))
}

/// Reads one request's head from `stream`, answers it, and closes.
fn connection(stream: &TcpStream, handler: &dyn Handler, port: u16) -> io::Result<()> {
    prepare(stream)?;
    let mut head = [0u8; MAX_HEAD];
    let mut filled = 0;
    let (response, is_head) = loop {
        let n = (&*stream).read(&mut head[filled..])?;
        if n == 0 {
            return Ok(());
        }
        filled += n;
        let mut headers = [httparse::EMPTY_HEADER; MAX_HEADERS];
        let mut request = httparse::Request::new(&mut headers);
        match request.parse(&head[..filled]) {
            Ok(httparse::Status::Complete(_)) => break answer(&request, handler, port),
            Ok(httparse::Status::Partial) if filled < MAX_HEAD => continue,
            Ok(httparse::Status::Partial) | Err(httparse::Error::TooManyHeaders) => {
                break (Response::refuse(431, "the request's head is too large"), false)
            }
            Err(e) => break (Response::refuse(400, &format!("not an HTTP request: {e}")), false),
        }
    };
    send(stream, is_head, &response)
}

/// The response to a parsed request, and whether it was a HEAD.
fn answer(request: &httparse::Request, handler: &dyn Handler, port: u16) -> (Response, bool) {
    let (Some(method), Some(target)) = (request.method, request.path) else {
        return (Response::refuse(400, "no method or path"), false);
    };
    let is_head = method == "HEAD";
    if method != "GET" && !is_head {
        return (Response::refuse(405, &format!("{method}: only GET is served")), false);
    }
    let host = request
        .headers
        .iter()
        .find(|h| h.name.eq_ignore_ascii_case("host"))
        .map(|h| h.value);
    let allowed = [format!("127.0.0.1:{port}"), format!("localhost:{port}")];
    if !host.is_some_and(|h| allowed.iter().any(|a| a.as_bytes() == h)) {
        return (
            Response::refuse(421, "the Host must be 127.0.0.1 or localhost with the port"),
            is_head,
        );
    }
    let (path, query) = target.split_once('?').unwrap_or((target, ""));
    let request = Request {
        path: path.to_string(),
        query: query.to_string(),
    };
    (handler.handle(&request), is_head)
}

/// Writes `response` (its head alone for a HEAD request).
fn send(stream: &TcpStream, is_head: bool, response: &Response) -> io::Result<()> {
    let reason = match response.status {
        200 => "OK",
        400 => "Bad Request",
        404 => "Not Found",
        405 => "Method Not Allowed",
        413 => "Content Too Large",
        421 => "Misdirected Request",
        431 => "Request Header Fields Too Large",
        500 => "Internal Server Error",
        503 => "Service Unavailable",
        _ => "",
    };
    let head = format!(
        "HTTP/1.1 {} {reason}\r\nContent-Type: {}\r\nContent-Length: {}\r\nCache-Control: no-store\r\n\
         X-Content-Type-Options: nosniff\r\nConnection: close\r\n\r\n",
        response.status,
        response.content_type,
        response.body.len()
    );
    let mut out = stream;
    out.write_all(head.as_bytes())?;
    if !is_head {
        out.write_all(&response.body)?;
    }
    out.flush()?;
    // Sent whole: the client reads to the end and sees the close.
    stream.shutdown(std::net::Shutdown::Write)
}
