//! What the console benchmarks share: child processes killed by pid when
//! dropped, a free loopback port, `--name value` arguments, the address a
//! console prints.

use std::io::{BufRead, BufReader};
use std::process::{Child, ChildStdout};

/// A child process killed (by pid) when dropped.
pub struct Proc(pub Child);

impl Drop for Proc {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// A free loopback port.
pub fn free_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0")
        .expect("a loopback port")
        .local_addr()
        .expect("its address")
        .port()
}

/// The value after `name` on the command line.
pub fn arg(name: &str) -> Option<String> {
    let args: Vec<String> = std::env::args().collect();
    args.iter()
        .position(|a| a == name)
        .and_then(|i| args.get(i + 1).cloned())
}

/// The address (with its token) a starting console prints on `stdout`;
/// what it prints after is read and dropped, so it never blocks on a full
/// pipe.
pub fn console_url(stdout: ChildStdout) -> anyhow::Result<String> {
    let mut lines = BufReader::new(stdout).lines();
    let url = lines
        .by_ref()
        .map_while(Result::ok)
        .find_map(|l| l.strip_prefix("console: open ").map(str::to_owned))
        .ok_or_else(|| anyhow::anyhow!("the console printed no address"))?;
    std::thread::spawn(move || lines.for_each(drop));
    Ok(url)
}
