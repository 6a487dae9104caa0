//! A network namespace joined to the root namespace by a veth pair, for the drills that cut
//! links with iptables (this kernel has no `tc netem`). Needs root, `ip` (iproute2) and
//! `iptables`; without them a drill fails saying so, never skips. Dropping it removes the
//! namespace (with the veth pair), also when the test fails.

use std::process::{Command, Stdio};

pub const REQUIREMENT: &str = "the network drills need root, `ip` (iproute2) and `iptables` \
                               (Debian: apt-get install iproute2 iptables); see tests/README.md";

/// Runs a command; its stdout, or a panic naming it and its stderr.
pub fn run(program: &str, args: &[&str]) -> String {
    let out = Command::new(program)
        .args(args)
        .output()
        .unwrap_or_else(|e| panic!("`{program} {}`: {e} ({REQUIREMENT})", args.join(" ")));
    assert!(
        out.status.success(),
        "`{program} {}` failed ({}): {}",
        args.join(" "),
        out.status,
        String::from_utf8_lossy(&out.stderr).trim()
    );
    String::from_utf8_lossy(&out.stdout).into_owned()
}

/// Fails loudly unless the drill can run: root, `ip` and `iptables`.
pub fn require_root_and_tools() {
    let status = std::fs::read_to_string("/proc/self/status").expect("/proc/self/status");
    let euid = status
        .lines()
        .find_map(|l| l.strip_prefix("Uid:"))
        .and_then(|ids| ids.split_whitespace().nth(1))
        .expect("an effective uid");
    assert!(euid == "0", "{REQUIREMENT}: running as uid {euid}");
    for tool in ["ip", "iptables"] {
        let ran = Command::new(tool)
            .arg("-V")
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .status();
        assert!(
            ran.is_ok_and(|s| s.success()),
            "{REQUIREMENT}: `{tool} -V` did not run"
        );
    }
}

/// A namespace and its veth pair: `host_ip` on the root side, `ns_ip` inside.
pub struct Netns {
    pub ns: String,
    pub host_if: String,
    pub host_ip: String,
    pub ns_ip: String,
}

impl Netns {
    /// A namespace named for `what` and this process, on a /30 no interface uses.
    pub fn create(what: &str) -> Netns {
        require_root_and_tools();
        let pid = std::process::id();
        let tag: String = what.chars().take(3).collect();
        let used = run("ip", &["-o", "-4", "addr", "show"]);
        let x = (0..250)
            .map(|i| (pid + i) % 250 + 1)
            .find(|x| !used.contains(&format!(" 10.231.{x}.")))
            .expect("a free 10.231.X.0/30");
        let net = Netns {
            ns: format!("levelmap-{what}-{pid}"),
            host_if: format!("lm{tag}{pid}h"),
            host_ip: format!("10.231.{x}.1"),
            ns_ip: format!("10.231.{x}.2"),
        };
        // Made before the first command: a setup failing halfway is torn down too.
        let (ns, host_if) = (net.ns.as_str(), net.host_if.as_str());
        let inner_if = format!("lm{tag}{pid}n");
        run("ip", &["netns", "add", ns]);
        run(
            "ip",
            &[
                "link", "add", host_if, "type", "veth", "peer", "name", &inner_if,
            ],
        );
        run("ip", &["link", "set", &inner_if, "netns", ns]);
        let host_cidr = format!("{}/30", net.host_ip);
        run("ip", &["addr", "add", &host_cidr, "dev", host_if]);
        run("ip", &["link", "set", host_if, "up"]);
        let ns_cidr = format!("{}/30", net.ns_ip);
        run("ip", &["-n", ns, "addr", "add", &ns_cidr, "dev", &inner_if]);
        run("ip", &["-n", ns, "link", "set", &inner_if, "up"]);
        run("ip", &["-n", ns, "link", "set", "lo", "up"]);
        net
    }

    /// `iptables` inside the namespace.
    pub fn iptables(&self, args: &[&str]) {
        let mut all = vec!["netns", "exec", &self.ns, "iptables"];
        all.extend_from_slice(args);
        run("ip", &all);
    }

    /// `command` to run inside the namespace (`ip netns exec` runs the same program there).
    pub fn wrap(&self, command: &Command) -> Command {
        let mut inside = Command::new("ip");
        inside
            .args(["netns", "exec", &self.ns])
            .arg(command.get_program())
            .args(command.get_args());
        inside
    }
}

impl Drop for Netns {
    fn drop(&mut self) {
        // Takes the veth pair with it once no process is left inside.
        let _ = Command::new("ip").args(["netns", "del", &self.ns]).output();
        let _ = Command::new("ip")
            .args(["link", "del", &self.host_if])
            .output();
    }
}
