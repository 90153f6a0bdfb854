//! Where `touchdown companion`'s MAVLink goes: one type for every link a user can name.
//!
//! The companion loop only needs two things of a link: the bytes that arrived, without
//! waiting, and a frame written whole. [`Endpoint`] gives exactly that for a UDP client
//! (`--udp`, optionally from a fixed local port), a UDP server (`--udp-listen`: it answers
//! whoever sent the last datagram, like MAVProxy's `udpin`), a TCP client (`--tcp`), a TCP
//! server that takes one client at a time (`--tcp-listen`) and a serial port (`--serial`).
//! Everything is non-blocking, so one thread runs the frames, the link and the signals.
//!
//! What happens when the peer goes away differs, because what a user expects does:
//! - `--tcp`: the autopilot (SITL) closed the connection, usually because it stopped; the
//!   run ends ([`Received::Closed`]) and the command reports it (exit status 2).
//! - `--tcp-listen`: the client (a ground station or bridge) left; the server waits for the
//!   next one, and frames meanwhile are not sent ([`Sent::NoPeer`]).
//! - UDP has no connection: a client keeps sending; a server keeps its last peer.

use std::fs::File;
use std::io::{self, ErrorKind, Read, Write};
use std::net::{SocketAddr, TcpListener, TcpStream, UdpSocket};
use std::path::Path;
use std::time::{Duration, Instant};

/// The link as the command line names it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum EndpointSpec {
    /// `--udp HOST:PORT`, from `local_port` (`--udp-local-port`) or any free port.
    UdpClient {
        /// Where to send.
        remote: String,
        /// Our source port; `None`: one the system picks.
        local_port: Option<u16>,
    },
    /// `--udp-listen ADDR:PORT`.
    UdpListen(String),
    /// `--tcp HOST:PORT`.
    TcpClient(String),
    /// `--tcp-listen ADDR:PORT`.
    TcpListen(String),
    /// `--serial PATH --baud N`.
    Serial {
        /// The tty.
        path: std::path::PathBuf,
        /// Its speed.
        baud: u32,
    },
}

/// The link options of a command line (clap lets at most one through; a command without one
/// of them passes `None`).
#[derive(Debug, Clone, Copy, Default)]
pub struct LinkOptions<'a> {
    /// `--serial PATH` and `--baud N`.
    pub serial: Option<(&'a Path, u32)>,
    /// `--tcp HOST:PORT`.
    pub tcp: Option<&'a str>,
    /// `--tcp-listen ADDR:PORT`.
    pub tcp_listen: Option<&'a str>,
    /// `--udp-listen ADDR:PORT`.
    pub udp_listen: Option<&'a str>,
    /// `--udp HOST:PORT` and `--udp-local-port`.
    pub udp: Option<(&'a str, Option<u16>)>,
}

impl LinkOptions<'_> {
    /// The link the options name, if any.
    pub fn spec(&self) -> Option<EndpointSpec> {
        Some(if let Some((path, baud)) = self.serial {
            EndpointSpec::Serial {
                path: path.to_path_buf(),
                baud,
            }
        } else if let Some(addr) = self.tcp {
            EndpointSpec::TcpClient(addr.to_string())
        } else if let Some(addr) = self.tcp_listen {
            EndpointSpec::TcpListen(addr.to_string())
        } else if let Some(addr) = self.udp_listen {
            EndpointSpec::UdpListen(addr.to_string())
        } else {
            let (remote, local_port) = self.udp?;
            EndpointSpec::UdpClient {
                remote: remote.to_string(),
                local_port,
            }
        })
    }
}

impl EndpointSpec {
    /// The option as the user wrote it, for messages.
    pub fn describe(&self) -> String {
        match self {
            EndpointSpec::UdpClient {
                remote,
                local_port: Some(port),
            } => format!("--udp {remote} (from local port {port})"),
            EndpointSpec::UdpClient { remote, .. } => format!("--udp {remote}"),
            EndpointSpec::UdpListen(addr) => format!("--udp-listen {addr}"),
            EndpointSpec::TcpClient(addr) => format!("--tcp {addr}"),
            EndpointSpec::TcpListen(addr) => format!("--tcp-listen {addr}"),
            EndpointSpec::Serial { path, .. } => format!("--serial {}", path.display()),
        }
    }
}

/// What a read found.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Received {
    /// `n` bytes at the front of the buffer (0: nothing waiting).
    Bytes(usize),
    /// The peer of a `--tcp` connection closed it: nothing more will come.
    Closed,
}

/// Why [`Endpoint::drain`] stopped: the link is gone.
#[derive(Debug)]
pub enum LinkLost {
    /// The peer of a `--tcp` connection closed it.
    Closed,
    /// The link failed (its error).
    Failed(io::Error),
}

impl core::fmt::Display for LinkLost {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            LinkLost::Closed => f.write_str("the peer closed the connection"),
            LinkLost::Failed(e) => write!(f, "{e}"),
        }
    }
}

/// What became of a frame handed to [`Endpoint::send`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Sent {
    /// Written whole.
    Sent,
    /// Nobody to send to yet (a server before its first peer, or between two TCP clients).
    NoPeer,
}

/// How long a write may wait for room (a full serial or TCP buffer) before it counts as a
/// send error: longer than any frame takes on a slow UART, shorter than the 1 s freshness
/// ArduPilot gives a target.
const WRITE_PATIENCE: Duration = Duration::from_millis(500);

/// An open link (see the module documentation).
#[derive(Debug)]
pub enum Endpoint {
    /// `--udp`: a connected datagram socket.
    UdpClient(UdpSocket),
    /// `--udp-listen`: a bound socket and the address of the last datagram's sender.
    UdpListen {
        /// The bound socket.
        socket: UdpSocket,
        /// Where replies go.
        peer: Option<SocketAddr>,
    },
    /// `--tcp`: a connected stream.
    TcpClient(TcpStream),
    /// `--tcp-listen`: the listening socket and the client, when one is connected.
    TcpListen {
        /// The listening socket.
        listener: TcpListener,
        /// The client, with its address.
        client: Option<(TcpStream, SocketAddr)>,
    },
    /// `--serial`: the tty, raw.
    Serial(File),
}

impl Endpoint {
    /// Opens (binds, connects) the link; a failure is the one-line reason.
    pub fn open(spec: &EndpointSpec) -> io::Result<Endpoint> {
        Ok(match spec {
            EndpointSpec::UdpClient { remote, local_port } => {
                let socket = UdpSocket::bind(("0.0.0.0", local_port.unwrap_or(0)))?;
                socket.connect(remote.as_str())?;
                socket.set_nonblocking(true)?;
                Endpoint::UdpClient(socket)
            }
            EndpointSpec::UdpListen(addr) => {
                let socket = UdpSocket::bind(addr.as_str())?;
                socket.set_nonblocking(true)?;
                Endpoint::UdpListen { socket, peer: None }
            }
            EndpointSpec::TcpClient(addr) => {
                let stream = TcpStream::connect(addr.as_str())?;
                // MAVLink frames are small and late ones are useless: no Nagle delay.
                stream.set_nodelay(true)?;
                stream.set_nonblocking(true)?;
                Endpoint::TcpClient(stream)
            }
            EndpointSpec::TcpListen(addr) => {
                let listener = TcpListener::bind(addr.as_str())?;
                listener.set_nonblocking(true)?;
                Endpoint::TcpListen {
                    listener,
                    client: None,
                }
            }
            EndpointSpec::Serial { path, baud } => Endpoint::Serial(open_serial(path, *baud)?),
        })
    }

    /// Whether the link only works once a peer has come to it (the servers): the run then
    /// waits for the first one before it starts the recording's clock.
    pub fn waits_for_peer(&self) -> bool {
        matches!(
            self,
            Endpoint::UdpListen { .. } | Endpoint::TcpListen { .. }
        )
    }

    /// The peer of a server, once one has come (always `None` for the other links).
    pub fn peer(&self) -> Option<SocketAddr> {
        match self {
            Endpoint::UdpListen { peer, .. } => *peer,
            Endpoint::TcpListen { client, .. } => client.as_ref().map(|(_, addr)| *addr),
            _ => None,
        }
    }

    /// The bytes waiting, without blocking; a TCP server takes a waiting client first.
    pub fn recv(&mut self, buf: &mut [u8]) -> io::Result<Received> {
        let read = match self {
            Endpoint::UdpClient(socket) => socket.recv(buf),
            Endpoint::UdpListen { socket, peer } => socket.recv_from(buf).map(|(n, from)| {
                *peer = Some(from);
                n
            }),
            Endpoint::TcpClient(stream) => match stream.read(buf) {
                Ok(0) => return Ok(Received::Closed),
                Err(e) if is_disconnect(&e) => return Ok(Received::Closed),
                other => other,
            },
            Endpoint::TcpListen { listener, client } => {
                if client.is_none() {
                    *client = accept(listener)?;
                }
                let Some((stream, _)) = client.as_mut() else {
                    return Ok(Received::Bytes(0));
                };
                match stream.read(buf) {
                    Ok(0) => {
                        *client = None;
                        return Ok(Received::Bytes(0));
                    }
                    Err(e) if is_disconnect(&e) => {
                        *client = None;
                        return Ok(Received::Bytes(0));
                    }
                    other => other,
                }
            }
            Endpoint::Serial(file) => file.read(buf),
        };
        match read {
            Ok(n) => Ok(Received::Bytes(n)),
            Err(e) if e.kind() == ErrorKind::WouldBlock => Ok(Received::Bytes(0)),
            // A UDP client hears ICMP "port unreachable" until the other end is up.
            Err(e) if e.kind() == ErrorKind::ConnectionRefused => Ok(Received::Bytes(0)),
            Err(e) => Err(e),
        }
    }

    /// Hands every byte waiting to `take`, read by read, until none is left: what each loop
    /// tick of `touchdown companion` and `touchdown sitl` does before it sends. A link that
    /// closed or failed ends the drain with why.
    pub fn drain(&mut self, buf: &mut [u8], mut take: impl FnMut(&[u8])) -> Result<(), LinkLost> {
        loop {
            match self.recv(buf) {
                Ok(Received::Bytes(0)) => return Ok(()),
                Ok(Received::Bytes(n)) => take(buf.get(..n).unwrap_or(&[])),
                Ok(Received::Closed) => return Err(LinkLost::Closed),
                Err(e) => return Err(LinkLost::Failed(e)),
            }
        }
    }

    /// Writes one MAVLink frame whole (a frame cut in two would corrupt a stream).
    pub fn send(&mut self, frame: &[u8]) -> io::Result<Sent> {
        match self {
            Endpoint::UdpClient(socket) => socket.send(frame).map(|_| Sent::Sent),
            Endpoint::UdpListen { socket, peer } => match peer {
                Some(to) => socket.send_to(frame, *to).map(|_| Sent::Sent),
                None => Ok(Sent::NoPeer),
            },
            Endpoint::TcpClient(stream) => write_whole(stream, frame).map(|()| Sent::Sent),
            Endpoint::TcpListen { client, .. } => {
                let Some((stream, _)) = client.as_mut() else {
                    return Ok(Sent::NoPeer);
                };
                let written = write_whole(stream, frame);
                if matches!(&written, Err(e) if is_disconnect(e)) {
                    *client = None;
                }
                written.map(|()| Sent::Sent)
            }
            Endpoint::Serial(file) => write_whole(file, frame).map(|()| Sent::Sent),
        }
    }
}

/// A waiting client of `listener`, made non-blocking, or `None`.
fn accept(listener: &TcpListener) -> io::Result<Option<(TcpStream, SocketAddr)>> {
    match listener.accept() {
        Ok((stream, addr)) => {
            stream.set_nodelay(true)?;
            stream.set_nonblocking(true)?;
            Ok(Some((stream, addr)))
        }
        Err(e) if e.kind() == ErrorKind::WouldBlock => Ok(None),
        Err(e) => Err(e),
    }
}

/// Whether a stream error means the peer is gone.
fn is_disconnect(e: &io::Error) -> bool {
    matches!(
        e.kind(),
        ErrorKind::ConnectionReset | ErrorKind::ConnectionAborted | ErrorKind::BrokenPipe
    )
}

/// `write_all` on a non-blocking stream: waits for room (up to [`WRITE_PATIENCE`]) instead
/// of failing half-way through a frame.
fn write_whole(w: &mut impl Write, mut bytes: &[u8]) -> io::Result<()> {
    let deadline = Instant::now() + WRITE_PATIENCE;
    while !bytes.is_empty() {
        match w.write(bytes) {
            Ok(0) => return Err(ErrorKind::WriteZero.into()),
            Ok(n) => bytes = bytes.get(n..).unwrap_or(&[]),
            Err(e) if e.kind() == ErrorKind::Interrupted => {}
            Err(e) if e.kind() == ErrorKind::WouldBlock => {
                if Instant::now() >= deadline {
                    return Err(ErrorKind::TimedOut.into());
                }
                std::thread::sleep(Duration::from_micros(200));
            }
            Err(e) => return Err(e),
        }
    }
    Ok(())
}

/// Opens a serial port raw (8N1, no echo, no flow control, non-blocking) at `baud`.
fn open_serial(path: &Path, baud: u32) -> io::Result<File> {
    use rustix::fs::{Mode, OFlags};
    use rustix::termios::{self, ControlModes, OptionalActions};
    // NOCTTY: the port must not become our controlling terminal.
    let fd = rustix::fs::open(
        path,
        OFlags::RDWR | OFlags::NOCTTY | OFlags::NONBLOCK | OFlags::CLOEXEC,
        Mode::empty(),
    )?;
    let mut t = termios::tcgetattr(&fd)?;
    t.make_raw();
    // Ignore modem lines (CLOCAL), enable the receiver (CREAD), no hardware flow control.
    t.control_modes |= ControlModes::CLOCAL | ControlModes::CREAD;
    t.control_modes -= ControlModes::CRTSCTS;
    t.set_speed(baud)?;
    termios::tcsetattr(&fd, OptionalActions::Now, &t)?;
    termios::tcflush(&fd, termios::QueueSelector::IFlush)?;
    Ok(File::from(fd))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A frame that does not fit the other end's buffer at once is still written whole.
    #[test]
    fn write_whole_waits_for_room() {
        struct Trickle(Vec<u8>, bool);
        impl Write for Trickle {
            fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
                // Every other call "the buffer is full"; otherwise one byte fits.
                self.1 = !self.1;
                if self.1 {
                    return Err(ErrorKind::WouldBlock.into());
                }
                self.0.push(buf[0]);
                Ok(1)
            }
            fn flush(&mut self) -> io::Result<()> {
                Ok(())
            }
        }
        let mut w = Trickle(Vec::new(), false);
        write_whole(&mut w, b"MAVLink").unwrap();
        assert_eq!(w.0, b"MAVLink");
    }

    #[test]
    fn udp_listen_answers_the_last_sender() {
        let mut server = Endpoint::open(&EndpointSpec::UdpListen("127.0.0.1:0".into())).unwrap();
        let Endpoint::UdpListen { socket, .. } = &server else {
            unreachable!()
        };
        let addr = socket.local_addr().unwrap();
        assert_eq!(server.send(b"x").unwrap(), Sent::NoPeer);
        let a = UdpSocket::bind("127.0.0.1:0").unwrap();
        let b = UdpSocket::bind("127.0.0.1:0").unwrap();
        let mut buf = [0u8; 16];
        for (from, byte) in [(&a, b'a'), (&b, b'b')] {
            from.send_to(&[byte], addr).unwrap();
            // Loopback delivers at once, but give the kernel a moment all the same.
            let mut got = Received::Bytes(0);
            for _ in 0..1000 {
                got = server.recv(&mut buf).unwrap();
                if got != Received::Bytes(0) {
                    break;
                }
                std::thread::sleep(Duration::from_millis(1));
            }
            assert_eq!(got, Received::Bytes(1));
            assert_eq!(server.peer(), Some(from.local_addr().unwrap()));
        }
        assert_eq!(server.send(b"reply").unwrap(), Sent::Sent);
        b.set_read_timeout(Some(Duration::from_secs(5))).unwrap();
        let n = b.recv(&mut buf).unwrap();
        assert_eq!(&buf[..n], b"reply");
    }
}
