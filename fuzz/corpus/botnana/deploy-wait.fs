: blink 3 0 do 10 ms pause loop ." done" cr ;
deploy blink ;deploy
