#!/usr/bin/env bash
# Makes a private CA and a certificate for the router (EXAMPLE; needs openssl).
#   deploy/make-certs.sh <router-ip> [out-dir]
set -euo pipefail
ip="${1:?router IP address}"
out="${2:-/etc/cosim/certs}"
mkdir -p "$out"
cd "$out"
openssl req -x509 -newkey rsa:3072 -nodes -days 825 -subj "/CN=cosim-ca" -keyout ca-key.pem -out ca.pem
openssl req -newkey rsa:3072 -nodes -subj "/CN=cosim-router" -keyout router-key.pem -out router.csr
printf 'subjectAltName=IP:%s\n' "$ip" > router.ext
openssl x509 -req -in router.csr -CA ca.pem -CAkey ca-key.pem -CAcreateserial -days 825 -extfile router.ext -out router.pem
rm -f router.csr router.ext
echo "CA: $out/ca.pem (copy to every machine); router: $out/router.pem, $out/router-key.pem"
