//! The HTTP half of `levelmap demo-localize`: captured scans sent to `POST …/localize`,
//! each answer scored against the truth and against the map.

use super::{TOKEN, distance};
use crate::bench_fleet::agent;
use anyhow::{Result, ensure};
use serde::Serialize;
use serde_json::{Value, json};
use slam::Pose2;
use std::collections::BTreeMap;
use std::time::Instant;

/// `POST …/localize` over the captured scans, one kind of prior.
#[derive(Serialize)]
pub(super) struct HttpFigures {
    pub(super) requests: usize,
    pub(super) found: usize,
    /// Within 0.10 m of the ground truth.
    pub(super) within_10cm: usize,
    pub(super) share_within_10cm: f64,
    /// Within 0.10 m of where the map puts the place (`MapErrors::relative`).
    pub(super) within_10cm_of_map: usize,
    /// Why the rest were not found: "not found", "ambiguous".
    pub(super) not_found: BTreeMap<String, usize>,
    pub(super) share_within_10cm_of_map: f64,
    pub(super) global_searches: usize,
    pub(super) rmse_found_m: f64,
    pub(super) median_ms: f64,
    pub(super) p90_ms: f64,
}

/// The prior sent with a scan, from its true pose.
type PriorOf = dyn Fn(&Pose2) -> Option<Value>;

pub(super) fn localize_over_http(
    http: &str,
    scans: &[(Pose2, Value)],
    map_errors: &MapErrors,
) -> Result<BTreeMap<&'static str, HttpFigures>> {
    let mut figures = BTreeMap::new();
    // Near the truth: the prior off by 0.3 m and 3°, σ 0.5 m and 0.1 rad (the defaults).
    let near = |t: &Pose2| Some(json!({"pose": t.compose(&Pose2::new(0.3, -0.2, 0.05))}));
    let none = |_: &Pose2| None;
    // Lost: 20 m off (the window of 3σ = 1.5 m does not hold the truth).
    let lost = |t: &Pose2| Some(json!({"pose": Pose2::new(t.x + 20.0, t.y, t.theta)}));
    let kinds: [(&'static str, &PriorOf); 3] = [
        ("prior", &near),
        ("no_prior", &none),
        ("prior_20m_off", &lost),
    ];
    for (kind, prior) in kinds {
        let (mut found, mut within, mut within_map, mut global) = (0, 0, 0, 0);
        let mut not_found = BTreeMap::<String, usize>::new();
        let mut took = Vec::new();
        let mut errors = Vec::new();
        for (truth, scan) in scans {
            let mut body = scan.clone();
            if let Some(p) = prior(truth) {
                body["prior"] = p;
            }
            let t = Instant::now();
            let answer = post_json(&format!("{http}/localize"), &body)?;
            took.push(t.elapsed().as_secs_f64() * 1e3);
            if answer["found"] != true {
                let reason = answer["reason"].as_str().unwrap_or_default();
                let kind = reason.split(':').next().unwrap_or_default().to_owned();
                *not_found.entry(kind).or_default() += 1;
            }
            if answer["found"] == true {
                found += 1;
                global += usize::from(answer["search"] == "global");
                let pose: Pose2 = serde_json::from_value(answer["pose"].clone())?;
                let e = distance(&pose, truth);
                errors.push(e);
                within += usize::from(e <= 0.10);
                within_map += usize::from(map_errors.relative(&pose, truth) <= 0.10);
            }
        }
        let rmse = (errors.iter().map(|e| e * e).sum::<f64>() / errors.len().max(1) as f64).sqrt();
        figures.insert(
            kind,
            HttpFigures {
                requests: scans.len(),
                found,
                within_10cm: within,
                share_within_10cm: within as f64 / scans.len().max(1) as f64,
                within_10cm_of_map: within_map,
                not_found,
                share_within_10cm_of_map: within_map as f64 / scans.len().max(1) as f64,
                global_searches: global,
                rmse_found_m: rmse,
                median_ms: percentile(&mut took, 0.5),
                p90_ms: percentile(&mut took, 0.9),
            },
        );
    }
    Ok(figures)
}

/// The survey map's own error: each node's estimate and its truth. Localization can be no
/// better than the map; its error against where the map puts a place is its error against
/// the truth less the map's error at the nearest map node.
#[derive(Clone)]
pub(super) struct MapErrors(pub(super) Vec<(Pose2, Pose2)>);

impl MapErrors {
    /// |(found − truth) − (estimate − truth of the map node nearest the truth)| (m).
    pub(super) fn relative(&self, found: &Pose2, truth: &Pose2) -> f64 {
        let Some((estimate, node_truth)) = self
            .0
            .iter()
            .min_by(|a, b| distance(&a.1, truth).total_cmp(&distance(&b.1, truth)))
        else {
            return distance(found, truth);
        };
        let map = [estimate.x - node_truth.x, estimate.y - node_truth.y];
        (found.x - truth.x - map[0]).hypot(found.y - truth.y - map[1])
    }
}

pub(super) fn percentile(values: &mut [f64], q: f64) -> f64 {
    if values.is_empty() {
        return f64::NAN;
    }
    values.sort_by(f64::total_cmp);
    values[((values.len() - 1) as f64 * q).round() as usize]
}

fn checked(mut response: ureq::http::Response<ureq::Body>, what: &str) -> Result<Value> {
    let status = response.status();
    let body = response.body_mut().read_to_string()?;
    ensure!(status.is_success(), "{what}: {status}: {body}");
    Ok(serde_json::from_str(&body)?)
}

pub(super) fn get_json(url: &str) -> Result<Value> {
    checked(agent().get(url).call()?, url)
}

pub(super) fn post_json(url: &str, body: &Value) -> Result<Value> {
    let response = agent()
        .post(url)
        .header("Authorization", format!("Bearer {TOKEN}"))
        .header("Content-Type", "application/json")
        .send(&serde_json::to_vec(body)?)?;
    checked(response, url)
}

pub(super) fn put_json(url: &str, body: &Value) -> Result<Value> {
    let response = agent()
        .put(url)
        .header("Authorization", format!("Bearer {TOKEN}"))
        .header("Content-Type", "application/json")
        .send(&serde_json::to_vec(body)?)?;
    checked(response, url)
}
