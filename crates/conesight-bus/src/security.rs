//! [`check_enforceable`]: auth and access-control settings this build cannot honour are an
//! error, never ignored (issue 15). Zenoh itself skips a `transport/auth/usrpwd` section when its
//! `auth_usrpwd` feature is off, and an endpoint of a protocol it was built without only fails
//! later, per link.

use zenoh::Config;

use crate::error::BusError;

/// Link protocols this build of Zenoh carries (the workspace's `zenoh` features
/// `transport_tcp` and `transport_tls`).
pub const LINK_PROTOCOLS: &[&str] = &["tcp", "tls"];

/// Whether Zenoh's user/password authentication is compiled in (this crate's feature
/// `auth_usrpwd`, which turns on `zenoh/auth_usrpwd`).
pub const AUTH_USRPWD: bool = cfg!(feature = "auth_usrpwd");

/// Whether Zenoh's public-key authentication is compiled in (feature `auth_pubkey`).
pub const AUTH_PUBKEY: bool = cfg!(feature = "auth_pubkey");

/// Refuses a config that asks for security this build cannot enforce:
/// - `transport/auth/usrpwd` or `transport/auth/pubkey` set without the Zenoh feature;
/// - a listen or connect endpoint, or a `transport/link/protocols` entry, of a protocol not in
///   [`LINK_PROTOCOLS`];
/// - `transport/link/tls/enable_mtls` with a non-`tls/` endpoint (that link would take peers
///   without certificates);
/// - `access_control` enabled without rules, subjects or policies, or with subjects keyed by
///   certificate CN while mTLS is off (no peer would ever match them).
pub fn check_enforceable(config: &Config) -> Result<(), BusError> {
    let usrpwd = json(config, "transport/auth/usrpwd");
    if !AUTH_USRPWD && has_value(&usrpwd) {
        return Err(unenforceable(
            "transport/auth/usrpwd",
            "is set, but this build of Zenoh has no user/password authentication (feature auth_usrpwd), so it would be ignored",
            "remove it and use mTLS with access control (deploy/zenoh/mtls.sh), or build with --features conesight-bus/auth_usrpwd",
        ));
    }
    let pubkey = json(config, "transport/auth/pubkey");
    if !AUTH_PUBKEY && has_value(&pubkey) {
        return Err(unenforceable(
            "transport/auth/pubkey",
            "is set, but this build of Zenoh has no public-key authentication (feature auth_pubkey), so it would be ignored",
            "remove it and use mTLS with access control (deploy/zenoh/mtls.sh), or build with --features conesight-bus/auth_pubkey",
        ));
    }
    let endpoints: Vec<(&'static str, String)> = ["listen/endpoints", "connect/endpoints"]
        .into_iter()
        .flat_map(|key| {
            strings(&json(config, key))
                .into_iter()
                .map(move |e| (key, e))
        })
        .collect();
    for (key, endpoint) in &endpoints {
        let protocol = endpoint.split('/').next().unwrap_or_default();
        if !LINK_PROTOCOLS.contains(&protocol) {
            return Err(unenforceable(
                key,
                format!(
                    "has the endpoint {endpoint}, a protocol this build of Zenoh does not carry"
                ),
                "use tcp/ or tls/ endpoints",
            ));
        }
    }
    for protocol in strings(&json(config, "transport/link/protocols")) {
        if !LINK_PROTOCOLS.contains(&protocol.as_str()) {
            return Err(unenforceable(
                "transport/link/protocols",
                format!("lists {protocol}, a protocol this build of Zenoh does not carry"),
                "list only tcp and/or tls",
            ));
        }
    }
    let mtls = json(config, "transport/link/tls/enable_mtls") == serde_json::Value::Bool(true);
    if mtls && let Some((key, endpoint)) = endpoints.iter().find(|(_, e)| !e.starts_with("tls/")) {
        return Err(unenforceable(
            key,
            format!(
                "has the endpoint {endpoint} while transport/link/tls/enable_mtls is on: that link would take peers without a certificate"
            ),
            "use tls/ endpoints only (--zenoh-listen tls/HOST:PORT, --zenoh-connect tls/HOST:PORT)",
        ));
    }
    if json(config, "access_control/enabled") == serde_json::Value::Bool(true) {
        for part in ["rules", "subjects", "policies"] {
            let value = json(config, &format!("access_control/{part}"));
            if value.as_array().is_none_or(Vec::is_empty) {
                return Err(unenforceable(
                    match part {
                        "rules" => "access_control/rules",
                        "subjects" => "access_control/subjects",
                        _ => "access_control/policies",
                    },
                    "is empty while access_control/enabled is true: the list would grant or deny nothing as intended",
                    "generate the list with deploy/zenoh/mtls.sh, or set access_control/enabled to false",
                ));
            }
        }
        let by_cn = json(config, "access_control/subjects")
            .as_array()
            .is_some_and(|subjects| {
                subjects
                    .iter()
                    .any(|subject| has_value(&subject["cert_common_names"]))
            });
        if by_cn && !mtls {
            return Err(unenforceable(
                "access_control/subjects",
                "names certificate CNs (cert_common_names) while transport/link/tls/enable_mtls is off: no peer presents a certificate, so no subject would ever match",
                "set transport/link/tls/enable_mtls: true with tls/ endpoints (deploy/zenoh/mtls.sh)",
            ));
        }
    }
    Ok(())
}

fn unenforceable(key: &'static str, problem: impl Into<String>, fix: &'static str) -> BusError {
    BusError::Unenforceable {
        key,
        problem: problem.into(),
        fix,
    }
}

/// The config's value at `key` (`null` when unset or unreadable).
fn json(config: &Config, key: &str) -> serde_json::Value {
    config
        .get_json(key)
        .ok()
        .and_then(|text| serde_json::from_str(&text).ok())
        .unwrap_or(serde_json::Value::Null)
}

/// Whether `value` sets anything: a non-null scalar, or a list/object with such a value inside.
fn has_value(value: &serde_json::Value) -> bool {
    match value {
        serde_json::Value::Null => false,
        serde_json::Value::Array(items) => items.iter().any(has_value),
        serde_json::Value::Object(fields) => fields.values().any(has_value),
        _ => true,
    }
}

/// Every string in `value`, also inside mode-dependent objects (`{ peer: [...], router: [...] }`).
fn strings(value: &serde_json::Value) -> Vec<String> {
    match value {
        serde_json::Value::String(text) => vec![text.clone()],
        serde_json::Value::Array(items) => items.iter().flat_map(strings).collect(),
        serde_json::Value::Object(fields) => fields.values().flat_map(strings).collect(),
        _ => Vec::new(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn config(json5: &str) -> Config {
        let mut config = Config::default();
        for line in json5.lines().filter(|l| !l.trim().is_empty()) {
            let (key, value) = line.split_once('=').unwrap();
            config.insert_json5(key.trim(), value.trim()).unwrap();
        }
        config
    }

    fn refused_key(json5: &str) -> &'static str {
        match check_enforceable(&config(json5)) {
            Err(BusError::Unenforceable { key, .. }) => key,
            other => panic!("expected Unenforceable, got {other:?}"),
        }
    }

    #[test]
    fn defaults_pass() {
        check_enforceable(&Config::default()).unwrap();
        check_enforceable(&config(r#"listen/endpoints = ["tcp/127.0.0.1:0"]"#)).unwrap();
    }

    #[test]
    fn usrpwd_without_the_feature_is_refused_with_the_fix() {
        if AUTH_USRPWD {
            return;
        }
        let json5 = r#"transport/auth/usrpwd = { user: "camera", password: "secret" }"#;
        assert_eq!(refused_key(json5), "transport/auth/usrpwd");
        let message = check_enforceable(&config(json5)).unwrap_err().to_string();
        assert!(message.contains("auth_usrpwd"), "{message}");
        assert!(message.contains("mtls.sh"), "{message}");
    }

    #[test]
    fn unknown_protocols_are_refused() {
        assert_eq!(
            refused_key(r#"connect/endpoints = ["quic/127.0.0.1:7447"]"#),
            "connect/endpoints"
        );
        assert_eq!(
            refused_key(r#"transport/link/protocols = ["udp"]"#),
            "transport/link/protocols"
        );
        check_enforceable(&config(r#"listen/endpoints = ["tls/127.0.0.1:0"]"#)).unwrap();
    }

    #[test]
    fn mtls_with_a_tcp_endpoint_is_refused() {
        let json5 = "transport/link/tls/enable_mtls = true\n\
                     listen/endpoints = [\"tls/127.0.0.1:0\"]\n\
                     connect/endpoints = [\"tcp/127.0.0.1:7447\"]";
        assert_eq!(refused_key(json5), "connect/endpoints");
    }

    #[test]
    fn empty_or_unmatchable_access_control_is_refused() {
        assert_eq!(
            refused_key("access_control/enabled = true"),
            "access_control/rules"
        );
        let acl = r#"access_control = { enabled: true, default_permission: "deny",
            rules: [{ id: "r", messages: ["put"], flows: ["ingress"], permission: "allow", key_exprs: ["a/**"] }],
            subjects: [{ id: "s", cert_common_names: ["camera"] }],
            policies: [{ rules: ["r"], subjects: ["s"] }] }"#
            .replace('\n', " ");
        assert_eq!(
            refused_key(&format!("{acl}\nlisten/endpoints = [\"tcp/127.0.0.1:0\"]")),
            "access_control/subjects"
        );
        check_enforceable(&config(&format!(
            "{acl}\ntransport/link/tls/enable_mtls = true\nlisten/endpoints = [\"tls/127.0.0.1:0\"]"
        )))
        .unwrap();
        // Disabled, an empty list is fine.
        check_enforceable(&config("access_control/enabled = false")).unwrap();
    }
}
