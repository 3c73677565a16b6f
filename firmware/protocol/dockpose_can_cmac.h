/* SPDX-License-Identifier: MIT */
/*
 * The MAC of the dockpose CAN protocol's authentication (dockpose_can.h,
 * MacFunction) with OpenSSL: AES-128-CMAC (RFC 4493, NIST SP 800-38B, as
 * AUTOSAR SecOC uses), through OpenSSL 3's EVP_MAC. For both ends: the sensor
 * and a controller that has OpenSSL (link libcrypto). Header-only, C++17.
 *
 * Allocates: setKey() (OpenSSL's contexts, once); mac32() and cmac() never
 * (the context is re-initialised with its key, tests/firmware/test_can_auth.cpp
 * counts OpenSSL's allocations). Threads: one owner.
 */
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>

#include <openssl/core_names.h>
#include <openssl/evp.h>
#include <openssl/params.h>

#include "dockpose_can.h" /* next to this one, in the tree and installed */

namespace dockpose::can {

constexpr std::size_t kKeyBytes = 16; /* AES-128 */

class OpensslCmac final : public MacFunction
{
public:
	OpensslCmac() = default;
	OpensslCmac(const OpensslCmac &) = delete;
	OpensslCmac &operator=(const OpensslCmac &) = delete;
	~OpensslCmac() override { release(); }

	/* Use this 16-byte key. False when OpenSSL has no AES-128 CMAC (then every MAC fails). */
	bool setKey(const std::array<std::uint8_t, kKeyBytes> &key)
	{
		release();
		mac_ = EVP_MAC_fetch(nullptr, "CMAC", nullptr);
		if (!mac_)
			return false;
		ctx_ = EVP_MAC_CTX_new(mac_);
		if (!ctx_)
			return false;
		char cipher[] = "AES-128-CBC";
		const OSSL_PARAM params[] = {
			OSSL_PARAM_construct_utf8_string(OSSL_MAC_PARAM_CIPHER, cipher, 0),
			OSSL_PARAM_construct_end(),
		};
		ready_ = EVP_MAC_init(ctx_, key.data(), key.size(), params) == 1;
		return ready_;
	}

	bool ready() const { return ready_; }

	/* The whole 16-byte CMAC of data[0..len). */
	bool cmac(const std::uint8_t *data, std::size_t len, std::array<std::uint8_t, 16> *out)
	{
		if (!ready_)
			return false;
		/* A null key re-initialises the context with the key it has. */
		std::size_t out_len = 0;
		return EVP_MAC_init(ctx_, nullptr, 0, nullptr) == 1 &&
		       EVP_MAC_update(ctx_, data, len) == 1 &&
		       EVP_MAC_final(ctx_, out->data(), &out_len, out->size()) == 1 &&
		       out_len == out->size();
	}

	bool mac32(const std::uint8_t *data, std::size_t len, std::uint32_t *mac) override
	{
		std::array<std::uint8_t, 16> full{};
		if (!cmac(data, len, &full))
			return false;
		*mac = (std::uint32_t{ full[0] } << 24) | (std::uint32_t{ full[1] } << 16) |
		       (std::uint32_t{ full[2] } << 8) | full[3];
		return true;
	}

private:
	void release()
	{
		EVP_MAC_CTX_free(ctx_);
		EVP_MAC_free(mac_);
		ctx_ = nullptr;
		mac_ = nullptr;
		ready_ = false;
	}

	EVP_MAC *mac_ = nullptr;
	EVP_MAC_CTX *ctx_ = nullptr;
	bool ready_ = false;
};

} /* namespace dockpose::can */
