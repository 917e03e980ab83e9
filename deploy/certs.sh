#!/usr/bin/env bash
# deploy/certs.sh OUT_DIR [--new-ca] [NODE...]
#
# A certificate authority and one key + certificate per node for Zenoh mTLS (deploy/README.md,
# "mTLS and access control"). Each node certificate has the node's name as its CN, which the
# access-control list (deploy/zenoh/acl.json5) keys on. Default nodes: camera detector keypoints
# localiser recorder dashboard; name others to add them (a new node needs a certificate from the
# same CA and a subject in the ACL).
#
# OUT_DIR/ca.pem ca.key           the CA (kept when re-run; --new-ca replaces it)
# OUT_DIR/<node>.pem <node>.key   the node's certificate and key, re-issued on every run
#
# Node certificates carry subjectAltName DNS:<node>, DNS:localhost, IP:127.0.0.1 plus
# CONESIGHT_CERT_SANS (comma separated, e.g. "DNS:jetson.local,IP:10.0.0.2"), so a peer that
# dials a node by its compose service name, by localhost or by an address listed there can check
# the name. Valid CONESIGHT_CERT_DAYS days (default 365); the CA 3650 days.
set -euo pipefail

usage() { echo "usage: $0 OUT_DIR [--new-ca] [NODE...]" >&2; exit 2; }
[ $# -ge 1 ] || usage
out=$1
shift
new_ca=0
nodes=()
for arg in "$@"; do
  case $arg in
    --new-ca) new_ca=1 ;;
    -*) usage ;;
    *) nodes+=("$arg") ;;
  esac
done
[ ${#nodes[@]} -gt 0 ] || nodes=(camera detector keypoints localiser recorder dashboard)
command -v openssl >/dev/null 2>&1 || {
  echo "certs.sh: openssl is missing (Debian: apt-get install openssl; scripts/setup.sh runtime)" >&2
  exit 1
}
days=${CONESIGHT_CERT_DAYS:-365}
mkdir -p "$out"
umask 077

if [ "$new_ca" = 1 ] || [ ! -s "$out/ca.pem" ] || [ ! -s "$out/ca.key" ]; then
  openssl genpkey -algorithm EC -pkeyopt ec_paramgen_curve:P-256 -out "$out/ca.key" 2>/dev/null
  openssl req -x509 -new -key "$out/ca.key" -sha256 -days 3650 -subj "/CN=conesight-ca" \
    -addext "basicConstraints=critical,CA:TRUE" \
    -addext "keyUsage=critical,keyCertSign,cRLSign" \
    -out "$out/ca.pem"
  echo "certs.sh: new CA $out/ca.pem"
else
  echo "certs.sh: keeping CA $out/ca.pem (--new-ca to replace it)"
fi

for node in "${nodes[@]}"; do
  case $node in
    *[!A-Za-z0-9_-]* | '') echo "certs.sh: bad node name '$node'" >&2; exit 2 ;;
  esac
  sans="DNS:$node,DNS:localhost,IP:127.0.0.1${CONESIGHT_CERT_SANS:+,$CONESIGHT_CERT_SANS}"
  ext=$(mktemp)
  printf '%s\n' "basicConstraints=critical,CA:FALSE" \
    "keyUsage=critical,digitalSignature,keyEncipherment" \
    "extendedKeyUsage=serverAuth,clientAuth" \
    "subjectAltName=$sans" >"$ext"
  openssl genpkey -algorithm EC -pkeyopt ec_paramgen_curve:P-256 -out "$out/$node.key" 2>/dev/null
  openssl req -new -key "$out/$node.key" -subj "/CN=$node" -out "$out/$node.csr"
  openssl x509 -req -in "$out/$node.csr" -CA "$out/ca.pem" -CAkey "$out/ca.key" \
    -CAcreateserial -days "$days" -sha256 -extfile "$ext" -out "$out/$node.pem" 2>/dev/null
  rm -f "$out/$node.csr" "$ext"
  echo "certs.sh: $out/$node.pem (CN=$node)"
done
# Readable by the containers' uid 10001 only through the mount; keys stay 0600 on the host.
chmod 0644 "$out"/*.pem
