#!/usr/bin/env bash
# deploy/zenoh/mtls.sh CERT_DIR OUT_DIR [CERT_DIR_IN_CONFIG] [NODE...]
#
# Writes OUT_DIR/<node>.json5 for every node: deploy/zenoh/peer.json5's settings, mTLS on every
# link (tls/ endpoints only, the node's key and certificate from deploy/certs.sh for both
# listening and connecting, the peer's certificate required) and the default-deny access-control
# list keyed by certificate CN (the same list in every node; see deploy/README.md, "mTLS and
# access control"). The paths written into the configs are CERT_DIR_IN_CONFIG (default: CERT_DIR
# made absolute), e.g. /opt/conesight/certs where compose mounts the directory.
#
# Who may do what (everything else is denied):
#   node       puts                                      subscribes to
#   camera     frame, camera_info, detections (truth)    cones (pacing by the localiser)
#   detector   detections                                frame
#   keypoints  keypoints                                 frame, detections
#   localiser  cones                                     keypoints, camera_info
#   recorder   -                                         everything (and may query)
#   dashboard  -                                         everything (and may query)
# Every node announces itself (liveliness token, queryables); only observers get replies.
# Ingress rules say what a node accepts from a peer (keyed by the peer's CN); egress rules say what
# a node sends to a peer (a put only on the keys that peer may read).
set -euo pipefail

[ $# -ge 2 ] || { echo "usage: $0 CERT_DIR OUT_DIR [CERT_DIR_IN_CONFIG] [NODE...]" >&2; exit 2; }
cert_dir=$(cd "$1" && pwd)
out=$2
in_config=${3:-$cert_dir}
shift 2
[ $# -gt 0 ] && shift
nodes=("$@")
[ ${#nodes[@]} -gt 0 ] || nodes=(camera detector keypoints localiser recorder dashboard)
mkdir -p "$out"

key() { printf '"conesight/*/*/*/%s"' "$1"; }
# Services announce themselves under the verbatim chunk @service, which no `**` matches.
services_key='"conesight/*/*/@service/**"'
acl() {
  cat <<EOF
  access_control: {
    enabled: true,
    default_permission: "deny",
    rules: [
      // What a node accepts from each peer (ingress, keyed by the sender's CN).
      { id: "camera_puts", messages: ["put"], flows: ["ingress"], permission: "allow",
        key_exprs: [$(key frame), $(key camera_info), $(key detections)] },
      { id: "detector_puts", messages: ["put"], flows: ["ingress"], permission: "allow",
        key_exprs: [$(key detections)] },
      { id: "keypoints_puts", messages: ["put"], flows: ["ingress"], permission: "allow",
        key_exprs: [$(key keypoints)] },
      { id: "localiser_puts", messages: ["put"], flows: ["ingress"], permission: "allow",
        key_exprs: [$(key cones)] },
      { id: "camera_reads", messages: ["declare_subscriber"], flows: ["ingress"], permission: "allow",
        key_exprs: [$(key cones)] },
      { id: "detector_reads", messages: ["declare_subscriber"], flows: ["ingress"], permission: "allow",
        key_exprs: [$(key frame)] },
      { id: "keypoints_reads", messages: ["declare_subscriber"], flows: ["ingress"], permission: "allow",
        key_exprs: [$(key frame), $(key detections)] },
      { id: "localiser_reads", messages: ["declare_subscriber"], flows: ["ingress"], permission: "allow",
        key_exprs: [$(key keypoints), $(key camera_info)] },
      { id: "observer_reads", messages: ["declare_subscriber", "query", "declare_liveliness_subscriber", "liveliness_query"],
        flows: ["ingress"], permission: "allow", key_exprs: ["conesight/**", $services_key] },
      // What a node sends to each peer (egress, keyed by the receiver's CN): samples only on the
      // keys the receiver may read; its own subscriptions and queries to any known node.
      { id: "to_camera", messages: ["put"], flows: ["egress"], permission: "allow",
        key_exprs: [$(key cones)] },
      { id: "to_detector", messages: ["put"], flows: ["egress"], permission: "allow",
        key_exprs: [$(key frame)] },
      { id: "to_keypoints", messages: ["put"], flows: ["egress"], permission: "allow",
        key_exprs: [$(key frame), $(key detections)] },
      { id: "to_localiser", messages: ["put"], flows: ["egress"], permission: "allow",
        key_exprs: [$(key keypoints), $(key camera_info)] },
      { id: "to_observer", messages: ["put", "reply"], flows: ["egress"], permission: "allow",
        key_exprs: ["conesight/**", $services_key] },
      { id: "own_interest", messages: ["declare_subscriber", "query", "declare_liveliness_subscriber", "liveliness_query"],
        flows: ["egress"], permission: "allow", key_exprs: ["conesight/**", $services_key] },
      // Every node's presence: its liveliness token and the queryables of its latest outputs
      // and health/manifest/schema (answers go to observers only: to_observer).
      { id: "announce", messages: ["declare_queryable", "liveliness_token"],
        flows: ["egress", "ingress"], permission: "allow", key_exprs: ["conesight/**", $services_key] },
      // Answers to a node's own queries (only observers query; the senders only reply to them).
      { id: "answers", messages: ["reply"], flows: ["ingress"], permission: "allow",
        key_exprs: ["conesight/**", $services_key] },
    ],
    subjects: [
      { id: "camera", cert_common_names: ["camera"] },
      { id: "detector", cert_common_names: ["detector"] },
      { id: "keypoints", cert_common_names: ["keypoints"] },
      { id: "localiser", cert_common_names: ["localiser"] },
      { id: "observer", cert_common_names: ["recorder", "dashboard"] },
      { id: "member", cert_common_names: ["camera", "detector", "keypoints", "localiser", "recorder", "dashboard"] },
    ],
    policies: [
      { id: "camera", subjects: ["camera"], rules: ["camera_puts", "camera_reads", "to_camera"] },
      { id: "detector", subjects: ["detector"], rules: ["detector_puts", "detector_reads", "to_detector"] },
      { id: "keypoints", subjects: ["keypoints"], rules: ["keypoints_puts", "keypoints_reads", "to_keypoints"] },
      { id: "localiser", subjects: ["localiser"], rules: ["localiser_puts", "localiser_reads", "to_localiser"] },
      { id: "observer", subjects: ["observer"], rules: ["observer_reads", "to_observer"] },
      { id: "member", subjects: ["member"], rules: ["own_interest", "announce", "answers"] },
    ],
  },
EOF
}

for node in "${nodes[@]}"; do
  for file in "$cert_dir/ca.pem" "$cert_dir/$node.pem" "$cert_dir/$node.key"; do
    [ -s "$file" ] || { echo "mtls.sh: $file is missing: run deploy/certs.sh $cert_dir first" >&2; exit 1; }
  done
  cat >"$out/$node.json5" <<EOF
// Zenoh config of the conesight node "$node" with mTLS and access control; written by
// deploy/zenoh/mtls.sh from the certificates of deploy/certs.sh. Do not edit: re-run the script.
// Endpoints given with --zenoh-listen / --zenoh-connect (CONESIGHT_ZENOH_LISTEN/_CONNECT) override
// the ones here and must be tls/ endpoints too.
{
  mode: "peer",
  connect: { timeout_ms: -1, exit_on_failure: false },
  listen: { endpoints: ["tls/0.0.0.0:7447"] },
  scouting: {
    multicast: { enabled: false },
    gossip: { enabled: true },
  },
  transport: {
    shared_memory: { enabled: true },
    link: {
      // Only TLS links: a tcp/ endpoint would bypass the certificates.
      protocols: ["tls"],
      tls: {
        root_ca_certificate: "$in_config/ca.pem",
        enable_mtls: true,
        listen_private_key: "$in_config/$node.key",
        listen_certificate: "$in_config/$node.pem",
        connect_private_key: "$in_config/$node.key",
        connect_certificate: "$in_config/$node.pem",
        // Peers learnt by gossip are dialled by address; identity is the CA-signed certificate
        // and the access-control list keys on its CN, not on the host name.
        verify_name_on_connect: false,
        close_link_on_expiration: true,
      },
    },
  },
$(acl)
}
EOF
  echo "mtls.sh: $out/$node.json5"
done
