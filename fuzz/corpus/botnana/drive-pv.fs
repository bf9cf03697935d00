: run-pv pv 1 1 op-mode! until-no-requests 1 1 reset-fault 1 1 until-no-fault 1 1 drive-on 1 1 until-drive-on 500 1 1 target-v! 20 ms 1 1 real-v@ . ;
deploy run-pv ;deploy
