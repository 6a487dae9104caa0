//! A server-sent event stream read by a test, its JSON events as they come.

use serde_json::Value;
use std::io::{BufRead, BufReader, Read};
use std::time::{Duration, Instant};

/// An SSE stream's JSON events, read as they come.
pub struct Sse {
    lines: std::io::Lines<BufReader<Box<dyn Read + Send>>>,
}

impl Sse {
    pub fn open(http: &str, path: &str) -> Sse {
        let agent: ureq::Agent = ureq::Agent::config_builder()
            .http_status_as_error(false)
            .build()
            .into();
        let answer = agent
            .get(format!("http://{http}{path}"))
            .call()
            .expect("the stream opens");
        assert_eq!(answer.status(), 200, "{path}");
        let reader: Box<dyn Read + Send> = Box::new(answer.into_body().into_reader());
        Sse {
            lines: BufReader::new(reader).lines(),
        }
    }

    pub fn next(&mut self) -> Value {
        loop {
            let line = self
                .lines
                .next()
                .expect("the stream goes on")
                .expect("a line");
            if let Some(data) = line.strip_prefix("data: ") {
                return serde_json::from_str(data).expect("JSON");
            }
        }
    }

    /// The events of the next `period`.
    pub fn during(&mut self, period: Duration) -> Vec<Value> {
        let until = Instant::now() + period;
        let mut out = Vec::new();
        while Instant::now() < until {
            out.push(self.next());
        }
        out
    }
}
