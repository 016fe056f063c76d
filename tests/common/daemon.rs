//! The spawned-daemon harness every test binary shares: `penumbra serve` (the binary under
//! test) on a loopback address with the given flags and environment, waited for until
//! `/readyz` answers 200, and killed when dropped however the test ends. Blocking on purpose
//! (a plain TCP exchange), so synchronous and async tests use it alike.

use std::io::{Read, Write};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

/// A running daemon: its process and its address.
pub struct Daemon {
    pub child: Child,
    /// `127.0.0.1:PORT`.
    pub address: String,
    /// `http://127.0.0.1:PORT`.
    pub base: String,
}

/// A free port on 127.0.0.1, as `127.0.0.1:PORT`.
pub fn free_address() -> String {
    std::net::TcpListener::bind("127.0.0.1:0").unwrap().local_addr().unwrap().to_string()
}

/// `penumbra serve --listen ADDRESS` with logs at `warn` to nowhere and the shipped model (no
/// measurement in the background: tests share two cores): add flags, environment or a stderr
/// pipe, then `Daemon::start` it.
pub fn serve_command(address: &str) -> Command {
    let mut command = Command::new(env!("CARGO_BIN_EXE_penumbra"));
    command.args(["serve", "--listen", address]).env("PENUMBRA_LOG", "warn").env("PENUMBRA_MODEL", "default").stderr(Stdio::null());
    command
}

impl Daemon {
    /// `penumbra serve` on a free port with `flags`, ready.
    pub fn spawn(flags: &[&str]) -> Self {
        let address = free_address();
        let mut command = serve_command(&address);
        command.args(flags);
        Self::start(command, &address)
    }

    /// Starts `command` (a `serve_command` listening on `address`) and waits until it is ready.
    pub fn start(mut command: Command, address: &str) -> Self {
        let child = command.spawn().expect("the daemon starts");
        let daemon = Self { child, address: address.to_owned(), base: format!("http://{address}") };
        daemon.wait_ready(Duration::from_secs(60));
        daemon
    }

    /// Waits until `/readyz` answers 200; panics after `limit`.
    pub fn wait_ready(&self, limit: Duration) {
        let started = Instant::now();
        while started.elapsed() < limit {
            if status(&self.address, "/readyz") == Some(200) {
                return;
            }
            std::thread::sleep(Duration::from_millis(100));
        }
        panic!("the daemon at {} did not become ready in {limit:?}", self.base);
    }
}

impl Drop for Daemon {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// The status of `GET path` on `address`, or None when nothing answers.
pub fn status(address: &str, path: &str) -> Option<u16> {
    let mut stream = std::net::TcpStream::connect(address).ok()?;
    stream.set_read_timeout(Some(Duration::from_secs(5))).ok()?;
    write!(stream, "GET {path} HTTP/1.1\r\nHost: {address}\r\nConnection: close\r\n\r\n").ok()?;
    let mut head = [0u8; 12];
    stream.read_exact(&mut head).ok()?;
    std::str::from_utf8(&head[9..12]).ok()?.parse().ok()
}
